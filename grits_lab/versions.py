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

import functools
import platform
import subprocess
from importlib import metadata
from pathlib import Path

PROTOCOL_VERSION = 12
PROTOCOL = f"scoop-v{PROTOCOL_VERSION}"
# The Gymnasium env's own version (grits_lab.sim.ENV_ID, "grits_lab/Scoop-v<N>"): it names the scoop
# env alone (the world, foods and levels, physics, its spaces), not the stages after the scoop, so it
# bumps only when the env changes. It is 12 because the id followed the protocol until scoop-v12.
ENV_VERSION = 12

# What each version names, as a fingerprint per version (docs/protocol.md, "When to bump"):
# tests/test_versions.py recomputes the current ones and fails when what a version names changed
# without a bump, or a version was bumped while what it names stayed the same.
ENV_FINGERPRINTS = {12: "8c16d69d9cb380cc"}
PROTOCOL_FINGERPRINTS = {12: "17c5525a2c9ebaab"}

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


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (`platform.processor()` elsewhere); `unknown` when neither says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


@functools.lru_cache(maxsize=1)
def cpu_kernels() -> str:
    """The SIMD kernels this process's numeric libraries run, as one label, e.g.
    `numpy X86_V3+X86_V4+AVX512_ICL; openblas SkylakeX; torch AVX512`.

    NumPy, OpenBLAS and torch each pick kernels for the CPU at run time (NPY_DISABLE_CPU_FEATURES,
    OPENBLAS_CORETYPE and ATEN_CPU_CAPABILITY override the pick), and kernels of different widths
    round differently in the last bits. Contact amplifies those bits into another episode
    (studies/outcome_sensitivity/README.md), so two records of one seed with different labels
    are not expected to be equal, and a replay on other kernels is not expected to match. Imports
    torch (once per process) so that the label is the same whatever the process ran before.
    """
    import numpy  # noqa: F401  (loads OpenBLAS, for threadpoolctl to find)
    import threadpoolctl
    import torch

    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    parts = ["numpy " + ("+".join(f for f in __cpu_dispatch__ if __cpu_features__.get(f)) or "baseline")]
    for info in threadpoolctl.threadpool_info():
        if info.get("user_api") == "blas":
            parts.append(f"{info.get('internal_api')} {info.get('architecture') or '?'}")
    parts.append(f"torch {torch.backends.cpu.get_cpu_capability()}")
    return "; ".join(parts)
