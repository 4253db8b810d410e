"""Methods a lab brings without editing the package: a controller class named in the evaluation
config, or published by an installed package under the `grits_lab.methods` entry point group.

In the evaluation YAML:

    methods: [dp, my_policy]
    custom_methods:
      my_policy:
        controller: my_lab.controllers:MyController   # or path/to/file.py:MyController
        options: {weights: models/my_policy.pt}       # keyword arguments of MyController(...)
        description: our MLP policy

Or in the lab's own pyproject.toml (the method is then known to every config):

    [project.entry-points."grits_lab.methods"]
    my_policy = "my_lab.controllers:MyController"

The class implements the controller protocol of grits_lab/policies/control.py (`cloud_steps`,
`reset(scene)`, `plan(history, scene) -> Chunk | None`); each worker builds one instance per
episode with `options` as keyword arguments. The class is imported when the config loads, so a
misspelled module or class stops the command at once, naming `custom_methods.<name>.controller`.
Naming a file or module runs its code in the command and in every worker, as importing it does:
name only code you trust. A config entry wins over an entry point of the same name; a built-in method's name, or a class
inside grits_lab, is refused (the package's own methods are wired by name in methods.py).
examples/torch_controller.py wraps a plain torch policy this way.

Guidance parameters: a class whose constructor takes keyword arguments `rho` and `s` is a guided
method, like `grits`. It is built with `rho=guidance.rho, s=guidance.s` of the evaluation config
(so `grits-lab evaluate --override best.yaml` and each sweep trial reach it), its records carry
them in their `rho` / `s` columns, and a sweep (grits_lab/tune) can tune them. What they do to the
actions is the class's own business; `options` may not set them.
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import sys
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any

from grits_lab.errors import ConfigError

if TYPE_CHECKING:  # annotations only
    from grits_lab.sampling.guidance import GuidanceConfig

ENTRY_POINT_GROUP = "grits_lab.methods"
PROTOCOL = ("cloud_steps", "reset", "plan")
GUIDANCE_PARAMETERS = ("rho", "s")  # keyword arguments of a guided controller class, from `guidance.rho` / `guidance.s`


@dataclass
class CustomMethodConfig:
    """One registered method: `controller` "module:Class" or "file.py:Class", its keyword options."""

    controller: str
    options: dict[str, Any] = field(default_factory=dict)
    description: str = ""

    def __post_init__(self) -> None:
        module, _, name = self.controller.rpartition(":")
        if not module or not name.isidentifier():
            raise ConfigError(f"`controller` must be 'package.module:ClassName' or 'path/to/file.py:ClassName'. Got {self.controller!r}.")


def registered_methods(custom: dict[str, CustomMethodConfig] | None = None) -> dict[str, CustomMethodConfig]:
    """The entry points of installed packages, then `custom` (a config's `custom_methods`) over them."""
    found = {ep.name: CustomMethodConfig(ep.value, description=f"entry point {ep.value}") for ep in entry_points(group=ENTRY_POINT_GROUP)}
    return {**found, **(custom or {})}


def controller_class(method: str, spec: CustomMethodConfig) -> type:
    """Import the class `spec.controller` names; ConfigError naming the key when it cannot, or when
    the class lacks a part of the controller protocol."""
    key = f"custom_methods.{method}.controller"
    target, _, name = spec.controller.rpartition(":")
    if target.split(".")[0] == "grits_lab":
        raise ConfigError(f"`{key}`: {spec.controller!r} is inside grits_lab, whose methods are listed by name in `methods`")
    try:
        # An entry point's own loader: a config entry and an installed one resolve the same way.
        cls = getattr(_load_file(target), name) if target.endswith(".py") else EntryPoint(method, spec.controller, ENTRY_POINT_GROUP).load()
    except (ImportError, AttributeError, FileNotFoundError) as exc:
        raise ConfigError(f"`{key}`: cannot import {spec.controller!r} ({exc})") from None
    except Exception as exc:  # the lab's module raised while it loaded: name it, in one line
        raise ConfigError(f"`{key}`: importing {spec.controller!r} raised {type(exc).__name__}: {exc}") from None
    missing = [attr for attr in PROTOCOL if not hasattr(cls, attr)]
    if missing:
        raise ConfigError(f"`{key}`: {spec.controller} lacks {', '.join(missing)} of the controller protocol "
                          "(grits_lab/policies/control.py)")
    preset = [name for name in GUIDANCE_PARAMETERS if name in spec.options]
    if preset and not missing_guidance_parameters(cls):
        named = " and ".join(f"`{n}`" for n in preset)
        raise ConfigError(f"`custom_methods.{method}.options`: {named} of a guided controller {'is' if len(preset) == 1 else 'are'} "
                          f"set by {' and '.join(f'`guidance.{n}`' for n in preset)} (a sweep sets them per trial), not by its options")
    return cls


def missing_guidance_parameters(cls: type) -> list[str]:
    """The names of GUIDANCE_PARAMETERS that the constructor of `cls` does not take by keyword
    (a `**kwargs` catch-all does not count): empty for a guided controller class."""
    try:
        parameters = inspect.signature(cls).parameters
    except (TypeError, ValueError):  # a class whose signature cannot be read takes nothing we can name
        return list(GUIDANCE_PARAMETERS)
    by_keyword = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return [name for name in GUIDANCE_PARAMETERS if name not in parameters or parameters[name].kind not in by_keyword]


def build_custom_controller(method: str, spec: CustomMethodConfig, guidance: GuidanceConfig) -> Any:
    """A fresh controller of a registered method: its class called with `options`, and, for a
    guided class, with `rho` and `s` from `guidance` (the evaluation config's, a sweep trial's)."""
    cls = controller_class(method, spec)
    guided = {} if missing_guidance_parameters(cls) else {"rho": float(guidance.rho), "s": int(guidance.s)}
    try:
        return cls(**spec.options, **guided)
    except TypeError as exc:
        raise ConfigError(f"`custom_methods.{method}.options`: {exc}") from None


def _load_file(path: str) -> Any:
    """A module from a .py file, registered under a name made from a digest of its resolved path
    (two paths never share a module: `a_b/ctl.py` and `a/b_ctl.py` are two), so a second load
    (another episode in the same worker) returns the same module. Loading runs the file's code,
    as importing a module does; a file that raises while loading leaves no module behind."""
    resolved = Path(path).resolve()
    if not resolved.is_file():
        raise FileNotFoundError(f"no file {resolved}")
    digest = hashlib.sha256(str(resolved).encode()).hexdigest()[:16]
    name = f"grits_lab_custom_{''.join(c if c.isalnum() else '_' for c in resolved.stem)}_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    loader = importlib.util.spec_from_file_location(name, resolved)
    module = importlib.util.module_from_spec(loader)
    sys.modules[name] = module
    try:
        loader.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module
