"""The package's layering: every import in grits_lab points down, none goes through a string, and the
framework never imports a study (the top-level `studies` package beside it).

Read from the source (every `import` statement, module level or inside a function), so the rule
holds for the lazy imports the CLI's handlers make too. A package may import itself and any
package of a lower layer; two packages of one layer do not import each other.
"""

from __future__ import annotations

import ast
from pathlib import Path

import grits_lab

ROOT = Path(grits_lab.__file__).parent

# Lowest first; the foundation modules at the package's root come first.
LAYERS: list[set[str]] = [
    {"errors"},
    {"io", "seeding", "geometry", "intervals", "markdown", "versions"},
    {"config", "records"},
    {"runners", "training"},  # generic engines: parallel episodes, the torch training utilities
    {"sim"},
    {"perception"},
    {"task"},  # settings of the stages after the scoop, shared by evaluation and collection
    {"data"},  # storage only
    {"sampling"},
    {"policies", "spillage"},
    {"collection", "evaluation"},  # the jobs
    {"tune", "report"},
    {"pipeline"},
    {"cli"},
]
RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}


def _part(module: Path) -> str:
    """The package (or root module) of grits_lab that a source file belongs to."""
    rel = module.relative_to(ROOT)
    return rel.parts[0].removesuffix(".py")


def _imports(path: Path, top: str = "grits_lab") -> list[tuple[int, str]]:
    """(line, dotted module) of every import of package `top` in the file, relative imports resolved."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = ["grits_lab", *path.relative_to(ROOT).with_suffix("").parts]
    package = here[:-1]  # the package holding the file (an __init__'s own package)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                names = [".".join(base + ([node.module] if node.module else []))]
            else:
                names = [node.module or ""]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        found += [(node.lineno, n) for n in names if n == top or n.startswith(top + ".")]
    return found


def _study_imports() -> list[str]:
    """`file:line imports MODULE` for every import of `studies` in the framework."""
    return [f"{path.relative_to(ROOT)}:{line} imports {module}" for path in sorted(ROOT.rglob("*.py"))
            for line, module in _imports(path, "studies")]


def _violations() -> list[str]:
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        source = _part(path)
        if source == "__init__":
            continue
        assert source in RANK, f"{path.relative_to(ROOT)}: package {source!r} has no layer in tests/test_layering.py"
        for line, module in _imports(path):
            parts = module.split(".")
            if len(parts) < 2:
                continue  # `import grits_lab` (the version)
            target = parts[1]
            if target == source:
                continue
            assert target in RANK, f"{path.relative_to(ROOT)}:{line} imports {module}, which has no layer"
            if RANK[target] >= RANK[source]:
                out.append(f"{path.relative_to(ROOT)}:{line}: {source} (layer {RANK[source]}) imports {module} (layer {RANK[target]})")
    return out


def test_every_import_points_down_the_layers():
    assert _violations() == []


def test_the_framework_never_imports_a_study():
    assert _study_imports() == []


def _fake_package(tmp_path: Path, monkeypatch, package: str, files: dict[str, str]) -> None:
    """A grits_lab tree under `tmp_path` holding `files` in `package`, which the checkers read instead."""
    fake = tmp_path / "grits_lab"
    (fake / package).mkdir(parents=True)
    for name, text in files.items():
        (fake / package / name).write_text(text)
    monkeypatch.setattr(__import__(__name__, fromlist=["ROOT"]), "ROOT", fake)


def test_the_checker_sees_a_study_import(tmp_path, monkeypatch):
    """The rule is not vacuous: a report module importing a study, even lazily, is reported."""
    _fake_package(tmp_path, monkeypatch, "report", {"leak.py": "def f():\n    from studies.outcome_sensitivity import hooks\n",
                                                    "fine.py": "from grits_lab.report import tables\nimport studious\n"})
    assert _study_imports() == ["report/leak.py:2 imports studies.outcome_sensitivity"]


def test_no_package_reaches_another_through_importlib_or_a_module_path_string():
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        text = path.read_text()
        if "import_module(" in text or "__import__(" in text:
            offenders.append(str(path.relative_to(ROOT)))
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith(("grits_lab.", "studies.")) \
                    and ":" in node.value:
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.value!r}")
    assert offenders == []


def test_the_checker_sees_an_upward_import(tmp_path, monkeypatch):
    """The rule is not vacuous: a data module importing evaluation is reported."""
    _fake_package(tmp_path, monkeypatch, "data", {"leak.py": "def f():\n    from grits_lab.evaluation.evaluation_run import evaluate\n",
                                                  "fine.py": "from ..sim import foods\nfrom . import format\n"})
    assert _violations() == ["data/leak.py:2: data (layer 7) imports grits_lab.evaluation.evaluation_run (layer 10)"]


def test_every_package_exports_its_public_names_from_init():
    """One style: each package's __init__ imports its public names and lists them in __all__."""
    import importlib

    packages = sorted({p.parent for p in ROOT.rglob("__init__.py")} - {ROOT})
    for folder in packages:
        name = "grits_lab." + ".".join(folder.relative_to(ROOT).parts)
        if name == "grits_lab.cli":
            continue  # the command, not a library namespace: `main` and `build_parser`
        module = importlib.import_module(name)
        exported = getattr(module, "__all__", None)
        assert exported, f"{name} has no __all__"
        assert sorted(exported) == sorted(set(exported)), f"{name}.__all__ repeats a name"
        missing = [n for n in exported if n not in vars(module)]
        assert missing == [], f"{name}.__all__ names {missing}, which its __init__ does not import"
