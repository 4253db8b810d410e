"""What code produced a result: the task protocol's version, the git commit of the checkout holding
grits_lab, and package versions.

`PROTOCOL` names the task and its evaluation protocol (the world, the scripted stages, the
metrics and what a record holds), versioned as Gymnasium versions its envs: every change that
can move a result bumps `PROTOCOL_VERSION`, and docs/protocol.md lists each version, what changed
and which results it superseded. Every episode record, dataset manifest, checkpoint and report
stores it. Git and package versions are read from git and installed metadata, so no heavy
package is imported. Evaluation runs write them into provenance.json; reports add them for the
code that drew the report.
"""

from __future__ import annotations

import platform
import subprocess
from importlib import metadata
from pathlib import Path

PROTOCOL_VERSION = 12
PROTOCOL = f"scoop-v{PROTOCOL_VERSION}"

PACKAGES = ("grits-lab", "numpy", "pandas", "pyarrow", "matplotlib", "jinja2", "torch", "pybullet", "ray", "optuna", "open3d-cpu", "open3d")


def git_commit(where: Path | None = None) -> str:
    """`<sha>` or `<sha> (with uncommitted changes)` for the checkout holding grits_lab; `unknown` outside git."""
    where = where or Path(__file__).resolve().parents[1]
    try:
        sha = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        if sha.returncode != 0:
            return "unknown (not a git checkout)"
        dirty = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown (git not available)"
    suffix = " (with uncommitted changes)" if dirty.stdout.strip() else ""
    return sha.stdout.strip() + suffix


def package_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return versions
