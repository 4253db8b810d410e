"""Run the pipeline's stages in order, skipping each stage whose outputs match its current config.

A stage's fingerprint hashes its wired config file together with the fingerprints of the stages
it reads from, so changing the demonstrations re-trains the policy but leaves the predictor
alone. The state of finished stages lives in `<output_dir>/pipeline_state.json`, written
atomically after each stage; a stage interrupted half-way is simply run again and resumes
through its own resume logic (collections skip finished episodes, trainers load `last.pt`).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import yaml

from grits_lab.config import load_yaml, merge_mappings
from grits_lab.io import ensure_writable_dir, exclusive_directory, write_json_atomic, write_text_atomic
from grits_lab.pipeline.pipeline_config import UPSTREAM, PipelineConfig
from grits_lab.pipeline.stages import Layout, check, run, wire
from grits_lab.runners.executor_config import ExecutorConfig, check_reachable, cluster_address

STATE_FILE = "pipeline_state.json"
RAY_STAGES = ("demos", "spillage", "evaluate", "sweep")  # the stages that run episodes on Ray


def stage_config_text(stage: str, config: PipelineConfig, layout: Layout, tuned: bool = True) -> str:
    """The YAML a stage runs with: its file, the user's overrides, then the pipeline's links (for the
    evaluate stage after a sweep, the sweep's best guidance unless `tuned` is False: stages.wire)."""
    spec = config.stages[stage]
    data = load_yaml(spec.config) if spec.config else {}
    data = merge_mappings(data, spec.overrides)
    data = wire(stage, data, layout, set(config.stages), config.workers, config.address, tuned=tuned)
    header = f"# {stage} stage of pipeline `{config.name}`, generated from {spec.config or 'defaults'}\n"
    if tuned and stage == "evaluate" and "sweep" in config.stages and (layout.sweep_dir / "best.yaml").is_file():
        header += f"# guidance: the sweep stage's best point ({layout.sweep_dir / 'best.yaml'})\n"
    return header + yaml.safe_dump(data, sort_keys=False)


def holds_password(text: str) -> bool:
    """Whether a stage's wired YAML names a storage URL with a password (a sweep's `storage`).

    The stage runs from that file, so the password stays in it; the file is written owner-only."""
    from grits_lab.tune.storage import redact

    storage = (yaml.safe_load(text) or {}).get("storage")
    return isinstance(storage, str) and redact(storage) != storage


def fingerprint(text: str, upstream: list[str]) -> str:
    return hashlib.sha256((text + "|" + "|".join(upstream)).encode()).hexdigest()[:16]


def load_state(root: Path) -> dict[str, Any]:
    path = root / STATE_FILE
    if not path.exists():
        return {}
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError:
        print(f"warning: {path} is damaged; every stage will be checked again", file=sys.stderr)
        return {}


def run_pipeline(config: PipelineConfig, only: list[str] | None = None, force: list[str] | None = None,
                 progress: bool = True) -> dict[str, Any]:
    """Run (or resume) every configured stage; returns {stage: {status, seconds, fingerprint, summary}}.

    Every selected stage's wired config is parsed first (stages.check), so a bad key or food name
    in any stage raises ConfigError / InputError naming the stage before the first stage runs.
    """
    layout = Layout(Path(config.output_dir))
    stages = config.ordered_stages()
    texts = {stage: stage_config_text(stage, config, layout, tuned=False) for stage in stages}
    for stage in stages:  # a typo in the last stage's overrides fails now, not after the stages before it
        if not only or stage in only:
            check(stage, texts, config.stages[stage].config)
    if any(stage.split("_")[0] in RAY_STAGES for stage in stages if not only or stage in only):
        # a cluster that does not answer, or refuses this client's token, fails before any directory
        check_reachable(cluster_address(ExecutorConfig(address=config.address)))
    ensure_writable_dir(layout.root)
    with exclusive_directory(layout.root, "pipeline"):  # one pipeline per output directory: two would race on its state
        return _run_stages(config, layout, stages, texts, only, force, progress)


def _run_stages(config: PipelineConfig, layout: Layout, stages: list[str], texts: dict[str, str],
                only: list[str] | None, force: list[str] | None, progress: bool) -> dict[str, Any]:
    ensure_writable_dir(layout.configs)
    state = load_state(layout.root)
    fingerprints: dict[str, str] = {}
    results: dict[str, Any] = {}
    for index, stage in enumerate(stages, start=1):
        # the evaluate stage's text is taken now: a sweep stage before it has just written its best point
        text = stage_config_text(stage, config, layout) if stage == "evaluate" else texts[stage]
        upstream = [fingerprints[s] for s in UPSTREAM.get(stage, ()) if s in fingerprints]
        if stage == "sweep" and "evaluate" in texts:  # its trials run the evaluate stage's config
            upstream.append(fingerprint(texts["evaluate"], []))
        fp = fingerprint(text, upstream)
        fingerprints[stage] = fp
        previous = state.get(stage, {})
        if only and stage not in only:
            results[stage] = {"status": "not selected", "fingerprint": fp}
            continue
        if previous.get("fingerprint") == fp and previous.get("status") == "done" and stage not in (force or []):
            print(f"[{index}/{len(stages)}] {stage}: up to date, skipped", file=sys.stderr)
            results[stage] = {**previous, "status": "skipped"}
            continue
        if previous.get("fingerprint") not in (None, fp):
            # the config changed: the stage's old outputs would be resumed under the wrong config
            remove_outputs(layout.stage_outputs(stage))
            print(f"[{index}/{len(stages)}] {stage}: config changed, previous outputs removed", file=sys.stderr)
        config_path = layout.configs / f"{stage}.yaml"
        write_text_atomic(config_path, text, mode=0o600 if holds_password(text) else None)
        if stage == "sweep" and "evaluate" in texts:
            write_text_atomic(layout.sweep_evaluation_config, texts["evaluate"])
        print(f"[{index}/{len(stages)}] {stage}: running ({config_path})", file=sys.stderr)
        state[stage] = {"status": "running", "fingerprint": fp}
        write_json_atomic(layout.root / STATE_FILE, state)
        start = time.perf_counter()
        summary = run(stage, config_path, layout, progress)
        seconds = round(time.perf_counter() - start, 1)
        state[stage] = {"status": "done", "fingerprint": fp, "seconds": seconds,
                        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "summary": _jsonable(summary)}
        write_json_atomic(layout.root / STATE_FILE, state)
        results[stage] = state[stage]
        print(f"[{index}/{len(stages)}] {stage}: done in {seconds:.0f} s", file=sys.stderr)
    return results


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, default=str))


def remove_outputs(paths: list[Path]) -> None:
    """Remove a stage's outputs (files and folders under the pipeline's directory) before it re-runs
    under a changed config. A symbolic link is removed itself, never what it points at (a dataset
    linked in from elsewhere is kept); StorageError naming the path when one cannot be removed."""
    from grits_lab.errors import StorageError

    for path in paths:
        try:
            if path.is_symlink() or path.is_file():
                path.unlink()
            elif path.is_dir():
                shutil.rmtree(path)
        except OSError as exc:
            raise StorageError(f"cannot remove the earlier output {path}: {exc.strerror or exc}") from None
