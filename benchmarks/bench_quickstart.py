"""The main job from nothing, stage by stage, JSON output: `grits-lab pipeline experiments/quickstart.yaml`.

Runs the pipeline config (default experiments/quickstart.yaml) into an empty output folder in a
fresh process, packages already installed, and reports each stage's seconds (from the pipeline's
own pipeline_state.json), the total wall time against the budget (`--budget-s`, 600 s: the main
job's ten minutes), and the machine: CPU model, cores, memory, Python and torch builds, and the
1-minute load average sampled every 10 s during the run (its minimum, median and maximum; a load
above the core count means other jobs shared the machine, and every time here is slower for it).

Usage: python benchmarks/bench_quickstart.py [--config experiments/quickstart.yaml] [--output-dir results/benchmarks/quickstart_run]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def machine() -> dict:
    """CPU model, logical cores, memory (GiB) and the package builds that set the speed."""
    model = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("model name")), platform.processor()) if Path("/proc/cpuinfo").is_file() else platform.processor()
    memory = next((int(line.split()[1]) / 2**20 for line in Path("/proc/meminfo").read_text().splitlines()
                   if line.startswith("MemTotal")), None) if Path("/proc/meminfo").is_file() else None
    import torch

    return {"cpu": model, "cores": os.cpu_count(), "memory_gib": round(memory, 1) if memory else None,
            "python": platform.python_version(), "torch": torch.__version__, "platform": platform.platform()}


class LoadSampler(threading.Thread):
    """Samples the 1-minute load average every `interval` seconds until stopped."""

    def __init__(self, interval: float = 10.0) -> None:
        super().__init__(daemon=True)
        self.interval, self.samples, self._stop_event = interval, [os.getloadavg()[0]], threading.Event()

    def run(self) -> None:
        while not self._stop_event.wait(self.interval):
            self.samples.append(os.getloadavg()[0])

    def stop(self) -> dict:
        self._stop_event.set()
        self.join()
        return {"min": round(min(self.samples), 2), "median": round(statistics.median(self.samples), 2),
                "max": round(max(self.samples), 2), "samples": len(self.samples)}


def time_pipeline(config: Path, out: Path, timeout: float, budget_s: float = 600.0) -> dict:
    """Run `config` with its output_dir set to the emptied `out`; the stage times, the total and the load."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    data = yaml.safe_load(config.read_text())
    data["output_dir"] = str(out)
    wired = out.parent / f"{out.name}.yaml"
    wired.write_text(yaml.safe_dump(data, sort_keys=False))
    load = LoadSampler()
    load.start()
    start = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "grits_lab.cli", "pipeline", str(wired), "--no-progress"],
                              cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False)
        status = "ok" if proc.returncode == 0 else "failed"
    except subprocess.TimeoutExpired:
        proc, status = None, "timeout"
    seconds = round(time.perf_counter() - start, 1)
    state_path = out / "pipeline_state.json"
    stages = json.loads(state_path.read_text()) if state_path.exists() else {}
    result = {"config": str(config), "status": status, "seconds": seconds, "budget_s": budget_s,
              "within_budget": status == "ok" and seconds <= budget_s,
              "stage_seconds": {k: v.get("seconds") for k, v in stages.items()}, "load_1min": load.stop()}
    if proc is not None and proc.returncode != 0:
        result["error"] = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-5:])
    if proc is not None:
        result["closing_summary"] = [line for line in proc.stdout.splitlines() if line.strip()][-12:]
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "experiments" / "quickstart.yaml")
    parser.add_argument("--output-dir", type=Path, default=ROOT / "results" / "benchmarks" / "quickstart_run")
    parser.add_argument("--budget-s", type=float, default=600.0)
    parser.add_argument("--timeout", type=float, default=3600.0)
    args = parser.parse_args()
    result = {"benchmark": "quickstart", "machine": machine(),
              **time_pipeline(args.config, args.output_dir, args.timeout, args.budget_s)}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
