"""What a result was made with: the CPU kernels label follows what NumPy, OpenBLAS and torch really dispatch to."""

from __future__ import annotations

import os
import subprocess
import sys

from grits_lab.versions import cpu_kernels, cpu_model

LABEL = "from grits_lab.versions import cpu_kernels; import sys; print(cpu_kernels()); import torch; print(cpu_kernels())"


def _label(**env: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", LABEL], env={**os.environ, **env}, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.split("\n")[:2]


def test_the_label_names_numpy_and_blas_and_torch_once_imported():
    without, with_torch = _label()
    assert without.startswith("numpy ") and "; openblas " in without and "torch" not in without
    assert with_torch.startswith(without + "; torch ")
    assert cpu_kernels().startswith("numpy ") and cpu_model() != ""


def test_forced_kernels_change_the_label():
    # OPENBLAS_CORETYPE and ATEN_CPU_CAPABILITY pick narrower kernels than the CPU offers; every x86-64 CPU with AVX2 runs them.
    without, with_torch = _label(OPENBLAS_CORETYPE="Sandybridge", ATEN_CPU_CAPABILITY="default")
    assert "; openblas Sandybridge" in without
    assert with_torch.endswith("; torch DEFAULT")
    found = cpu_kernels().split(";")[0].removeprefix("numpy ")
    if found != "baseline":  # NumPy dispatches past its baseline here: switched off, its label says so
        assert _label(NPY_DISABLE_CPU_FEATURES=" ".join(found.split("+")))[0].startswith("numpy baseline;")
