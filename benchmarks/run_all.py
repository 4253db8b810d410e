"""Run every benchmark and write one JSON and one Markdown summary.

Each benchmark is its own script printing one JSON object; this runner calls them one after the
other in fresh processes (so one benchmark's threads or Ray instance never slows the next), keeps
their JSON whole, and pulls the headline figures into a Markdown table. Ratios (2 workers vs 1,
guided vs unguided) are taken inside one script's run, because absolute times on a shared
machine drift from minute to minute.

    python benchmarks/run_all.py                       # quick sizes, about 15 minutes on 2 cores
    python benchmarks/run_all.py --full                # larger repeats, every food, both presets
    python benchmarks/run_all.py --with-pipeline       # also time `grits-lab pipeline experiments/quickstart.yaml`

Outputs: results/benchmarks/summary.json and results/benchmarks/summary.md (or --output-dir DIR).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

from grits_lab.io import write_text_atomic

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def benchmark_commands(full: bool) -> dict[str, list[str]]:
    py = sys.executable
    return {
        "sim": [py, str(HERE / "bench_sim.py"), "--foods", "all" if full else "soybeans,sago,penne,milk_tea",
                "--render", "both", "--repeats", "2" if full else "1"],
        "runners": [py, str(HERE / "bench_runners.py"), "--episodes", "8" if full else "4"],
        "policy": [py, str(HERE / "bench_policy.py"), "--repeats", "20" if full else "5", "--train-steps", "50" if full else "10"],
        "predictor": [py, str(HERE / "bench_predictor.py"), "--repeats", "20" if full else "5"],
        "evaluation": [py, str(HERE / "bench_evaluation.py"), "--presets", *(["cpu", "paper"] if full else ["cpu"]),
                       "--repeats", "10" if full else "4", "--episodes", "4" if full else "2"],
        "sweep_pool": [py, str(HERE / "bench_sweep_pool.py"), "--trials", "6" if full else "3"],
        "transfer_ik": [py, str(HERE / "bench_transfer_ik.py"), "--repeats", "5" if full else "3"],
        # needs a demonstration dataset: grits-lab collect experiments/demos_quick.yaml
        "data_parallel": [py, str(HERE / "bench_data_parallel.py"), "--steps", "300" if full else "100"],
    }


def run_one(name: str, command: list[str], timeout: float) -> dict:
    start = time.perf_counter()
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    try:
        proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "seconds": round(time.perf_counter() - start, 1)}
    seconds = round(time.perf_counter() - start, 1)
    peak_mb = max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
        return {"status": "failed", "seconds": seconds, "returncode": proc.returncode, "error": "\n".join(tail)}
    text = proc.stdout.strip()
    try:
        result = json.loads(text[text.index("{"):])
    except ValueError:
        return {"status": "failed", "seconds": seconds, "error": "no JSON object in the output"}
    return {"status": "ok", "seconds": seconds, "peak_rss_mb_max_so_far": round(peak_mb, 1), "result": result}


def time_pipeline(timeout: float) -> dict:
    from bench_quickstart import time_pipeline as run  # this script's folder is on sys.path when run as a script

    return run(ROOT / "experiments" / "quickstart.yaml", ROOT / "results" / "benchmarks" / "pipeline_run", timeout)


def _median(values: list) -> float | None:
    values = sorted(v for v in values if v is not None)
    return values[len(values) // 2] if values else None


def _sim_rows(result: dict, render: str) -> list[dict]:
    return [row for row in result.get("results", []) if row.get("render") == render]


def headlines(name: str, result: dict) -> list[tuple[str, object]]:
    """The figures of one benchmark worth a line in the summary table."""
    if name == "sim":
        off, on = _sim_rows(result, "off"), _sim_rows(result, "on")
        return [
            ("simulated s per CPU s, rendering off (median over foods)", _median([r["sim_per_cpu"] for r in off])),
            ("simulated s per CPU s, rendering on (median over foods)", _median([r["sim_per_cpu"] for r in on])),
            ("simulated s per wall s, rendering off (median over foods)", _median([r["sim_per_wall"] for r in off])),
            ("episodes/min on one core, rendering off (CPU time)", _median([r["episodes_per_minute_cpu"] for r in off])),
            ("build + settle, CPU s (median)", _median([r["build_settle_cpu_s"] for r in off + on])),
        ]
    if name == "runners":
        keys = ["episodes_per_min_bare", "episodes_per_min_1", "episodes_per_min_2", "scaling_2_vs_1",
                "engine_overhead_2_workers", "peak_rss_mb_per_worker"]
        return [(key, result.get(key)) for key in keys]
    if name == "policy":
        return [(key, value) for key, value in result.items()
                if key.startswith(("train_steps_per_s", "plan_ms_batch", "guided_x0_over_unguided"))]
    if name == "data_parallel":
        return [(f"policy training, processes x threads {layout}: steps/s (vs the first)", f"{run['steps_per_s']} ({run.get('speedup')}x)")
                for layout, run in result.get("runs", {}).items()]
    if name == "predictor":
        return [(key, value) for key, value in result.items() if key.startswith("dp3_batch1")]
    if name == "sweep_pool":
        return [("sweep: overhead per trial, a pool per trial (s)", result.get("overhead_per_trial_before_s")),
                ("sweep: overhead per trial, one pool per sweep (s)", result.get("overhead_per_trial_now_s")),
                ("sweep: trial wall time, a pool per trial / one pool per sweep", result.get("ratio_trial_wall_before_over_now"))]
    if name == "transfer_ik":
        return [(f"transfer IK from the {start.replace('_', ' ')}: {key} (x PyBullet's solve)",
                 result.get(start, {}).get(f"{key}_over_solve")) for start in ("wound_wrist", "rest_posture")
                for key in ("refine_fine", "heading_free")]
    if name == "evaluation":
        rows = []
        for key, value in result.items():
            if isinstance(value, dict) and "ratio_guided_over_unguided" in value:
                rows.append((f"{key}: guided / unguided plan latency", value["ratio_guided_over_unguided"]))
            if isinstance(value, dict) and "episodes_per_minute" in value:
                rows.append((f"{key}: evaluation episodes/min", value["episodes_per_minute"]))
        return rows
    return []


def markdown(summary: dict) -> str:
    lines = [
        "# grits_lab benchmarks",
        "",
        f"Machine: {summary['machine']['cpus']} CPUs, {summary['machine']['platform']}, Python {summary['machine']['python']}; "
        f"run {summary['date']}. Ratios are taken within one script's run.",
        "",
        "| benchmark | figure | value |",
        "|---|---|---|",
    ]
    for bench, entry in summary["benchmarks"].items():
        if bench == "pipeline":
            continue
        if entry.get("status") != "ok":
            lines.append(f"| {bench} | (benchmark {entry.get('status')}) | |")
            continue
        for label, value in headlines(bench, entry["result"]):
            shown = f"{value:.3g}" if isinstance(value, float) else value
            lines.append(f"| {bench} | {label} | {shown} |")
    if "pipeline" in summary["benchmarks"]:
        p = summary["benchmarks"]["pipeline"]
        lines.append(f"| pipeline | quickstart end to end (s) | {p['seconds']} ({p['status']}) |")
    lines += ["", "Wall time of each benchmark script:", ""]
    lines += [f"- {name}: {entry.get('seconds')} s ({entry.get('status')})" for name, entry in summary["benchmarks"].items()]
    lines += ["", "The full JSON of every script is in summary.json."]
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="larger sizes (every food, both presets)")
    parser.add_argument("--only", nargs="+", help="run only these benchmarks")
    parser.add_argument("--with-pipeline", action="store_true", help="also time the quickstart pipeline end to end")
    parser.add_argument("--timeout", type=float, default=1800, help="seconds per benchmark")
    parser.add_argument("--output-dir", default=str(ROOT / "results" / "benchmarks"),
                        help="where summary.json and summary.md go (default: results/benchmarks)")
    args = parser.parse_args()
    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)

    summary = {
        "date": time.strftime("%Y-%m-%d %H:%M:%S%z"),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
        "benchmarks": {},
    }
    for name, command in benchmark_commands(args.full).items():
        if args.only and name not in args.only:
            continue
        print(f"running {name}: {' '.join(command[1:])}", file=sys.stderr, flush=True)
        summary["benchmarks"][name] = run_one(name, command, args.timeout)
        print(f"  {summary['benchmarks'][name]['status']} in {summary['benchmarks'][name]['seconds']} s", file=sys.stderr, flush=True)
    if args.with_pipeline:
        print("running the quickstart pipeline", file=sys.stderr, flush=True)
        summary["benchmarks"]["pipeline"] = time_pipeline(args.timeout * 2)
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2, default=str) + "\n")
    write_text_atomic(out / "summary.md", markdown(summary))
    print(markdown(summary))
    return 0 if all(b.get("status") == "ok" for b in summary["benchmarks"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
