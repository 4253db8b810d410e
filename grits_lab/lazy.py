"""Package namespaces that import their modules on first use.

The `grits-lab` command (grits_lab/cli/) builds its parser without importing any area, and a
handler imports only what it runs; if a package's `__init__` imported torch or pybullet eagerly,
every one-line config error would pay seconds for them. A package lists what it exports and
where it lives; the module is imported the first time a name is looked up.
"""

from __future__ import annotations

import importlib
from typing import Any, Callable


def lazy_exports(package: str, exports: dict[str, list[str]]) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """`(__getattr__, __dir__, __all__)` for `package`, given {submodule: [names it defines]}."""
    where = {name: f"{package}.{module}" for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> Any:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(where[name]), name)

    def __dir__() -> list[str]:
        return sorted(where)

    return __getattr__, __dir__, sorted(where)
