"""What a result was made with: the CPU kernels label follows what NumPy, OpenBLAS and torch really dispatch to."""

from __future__ import annotations

import os
import subprocess
import sys

from grits_lab.versions import cpu_kernels, cpu_model

LABEL = "from grits_lab.versions import cpu_kernels; print(cpu_kernels())"


def _label(first: str = "", **env: str) -> str:
    """The label a fresh process prints, after running `first`."""
    out = subprocess.run([sys.executable, "-c", f"{first}\n{LABEL}"], env={**os.environ, **env}, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_the_label_names_numpy_blas_and_torch_whatever_the_process_imported_before():
    label = _label()
    assert label.startswith("numpy ") and "; openblas " in label and "; torch " in label
    assert _label("import torch") == label == cpu_kernels()  # a Ray worker and a serial run agree
    assert cpu_model() != ""


def test_forced_kernels_change_the_label():
    # OPENBLAS_CORETYPE and ATEN_CPU_CAPABILITY pick narrower kernels than the CPU offers; every x86-64 CPU with AVX runs them.
    forced = _label(OPENBLAS_CORETYPE="Sandybridge", ATEN_CPU_CAPABILITY="default")
    assert "; openblas Sandybridge; " in forced and forced.endswith("; torch DEFAULT")
    found = cpu_kernels().split(";")[0].removeprefix("numpy ")
    if found != "baseline":  # NumPy dispatches past its baseline here: switched off, its label says so
        assert _label(NPY_DISABLE_CPU_FEATURES=" ".join(found.split("+"))).startswith("numpy baseline;")
