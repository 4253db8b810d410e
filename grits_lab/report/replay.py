"""Replaying one recorded evaluation episode: the same seed, checkpoints (checked by digest) and guidance, with a video.

An evaluation record holds everything that decides its episode: the seed, the method, the food
and level, the guidance setting (rho, s) and the digests of the checkpoints; the run directory's
`config.yaml` holds the rest. `replay_episode` re-runs the very episode in this process with the
same code path as `grits-lab evaluate` (grits_lab/evaluation/task_episode.py), compares every recorded
metric with the replayed one (exact equality; clocks excluded) and, when asked, renders a frame
from the video camera after the reset and after every action, captioned with method, food,
level, step and the spilled count. Rendering reads the simulator and never changes it, so the
replay with a video is the same episode as the one without.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from grits_lab.errors import InputError, StorageError
from grits_lab.records import CPU_KERNELS

# Record columns that measure time or name the machine: they differ between a run and its replay.
NOT_COMPARED = frozenset({"wall_time_s", "scoop_time_s", "transfer_time_s", "plan_time_mean_s", "plan_time_max_s", CPU_KERNELS})


@dataclass
class ReplayResult:
    """What a replay found. `mismatches`: column -> (recorded, replayed) for every metric that differs;
    `unrecorded`: metrics the replay measured that the record lacks (columns added since the run), with their values."""

    method: str
    food: str
    level: str
    trial: int
    seed: int
    rho: float
    s: int
    compared: list[str]
    mismatches: dict[str, tuple[Any, Any]] = field(default_factory=dict)
    video: str | None = None
    frames: int = 0
    replayed: dict[str, Any] = field(default_factory=dict)
    plan_figure: str | None = None
    unrecorded: dict[str, Any] = field(default_factory=dict)
    recorded_kernels: str | None = None
    replayed_kernels: str | None = None

    @property
    def matches(self) -> bool:
        return not self.mismatches

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method, "food": self.food, "level": self.level, "trial": self.trial, "seed": self.seed,
            "rho": None if math.isnan(self.rho) else self.rho, "s": self.s, "matches": self.matches,
            "compared": self.compared, "mismatches": {k: [_plain(a), _plain(b)] for k, (a, b) in self.mismatches.items()},
            "video": self.video, "frames": self.frames, "plan_figure": self.plan_figure,
            "unrecorded": {k: _plain(v) for k, v in self.unrecorded.items()},
            "recorded_kernels": self.recorded_kernels, "replayed_kernels": self.replayed_kernels,
        }

    def describe(self) -> str:
        """One line: the replay reproduced the record, or which metrics diverged and from which step."""
        head = f"{self.method} {self.food}/{self.level} trial {self.trial} (seed {self.seed})"
        tail = ("; measured, not in the record: " + ", ".join(f"{k} {_plain(v)}" for k, v in self.unrecorded.items())
                if self.unrecorded else "")
        if self.matches:
            return f"{head}: replay reproduces the record ({len(self.compared)} metrics equal){tail}"
        diffs = ", ".join(f"{k} {_plain(a)} -> {_plain(b)}" for k, (a, b) in self.mismatches.items())
        return f"{head}: replay DIVERGED from the record{self.divergence_step()}: {diffs}{tail}{self.kernels_note()}"

    def kernels_note(self) -> str:
        """Why a divergence may be expected: the record was made on other CPU kernels, or on kernels it does not name."""
        if self.recorded_kernels is None:
            return f" (the record does not name its CPU kernels; replayed on {self.replayed_kernels})"
        if self.recorded_kernels != self.replayed_kernels:
            return (f" (recorded on CPU kernels `{self.recorded_kernels}`, replayed on `{self.replayed_kernels}`: "
                    "kernels of another width round differently and contact amplifies it, docs/evaluation.md \"Outcome sensitivity\")")
        return ""

    def divergence_step(self) -> str:
        steps = []
        for key in ("first_spill_step", "completion_step", "scoop_steps"):
            if key in self.mismatches:
                a, b = self.mismatches[key]
                steps += [int(v) for v in (a, b) if v is not None and not _is_nan(v) and int(v) >= 0]
        return f" (by action {min(steps)})" if steps else ""


def _is_nan(value: Any) -> bool:
    return isinstance(value, float) and math.isnan(value)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):  # list columns (per-plan diagnostics) come back from Parquet as arrays
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    return None if _is_nan(value) else value


def _equal(recorded: Any, replayed: Any) -> bool:
    recorded, replayed = _plain(recorded), _plain(replayed)
    if recorded is None or replayed is None:
        return recorded is None and replayed is None
    if isinstance(recorded, (bool, np.bool_)) or isinstance(replayed, (bool, np.bool_)):
        return bool(recorded) == bool(replayed)
    return recorded == replayed


def load_record(run_dir: str | Path, *, method: str, food: str, level: str, trial: int) -> dict[str, Any]:
    """The one record of (method, food, level, trial) in RUN_DIR/episodes.parquet; InputError if none or several."""
    from grits_lab.evaluation.evaluation_run import RECORDS_FILE

    path = Path(run_dir) / RECORDS_FILE
    if not path.is_file():
        raise InputError(f"no {RECORDS_FILE} in {run_dir}: replay reads the run directory of `grits-lab evaluate`")
    frame = pd.read_parquet(path)
    rows = frame[(frame["method"] == method) & (frame["food"] == food) & (frame["level"].astype(str) == str(level))
                 & (frame["trial"].astype(int) == int(trial))]
    if rows.empty:
        have = sorted({(r.method, r.food, str(r.level)) for r in frame.itertuples()})
        listing = "; ".join(f"{m} {f}/{lv}" for m, f, lv in have[:12])
        raise InputError(f"{path}: no record of method {method!r}, food {food!r}, level {level!r}, trial {trial} "
                         f"(trials 0-{int(frame['trial'].max()) if len(frame) else -1}; records: {listing})")
    if len(rows) > 1:
        settings = ", ".join(f"rho={r.rho} s={r.s}" for r in rows.itertuples())
        raise InputError(f"{path}: {len(rows)} records of {method} {food}/{level} trial {trial} ({settings}); "
                         "replay runs from a run directory with one guidance setting per method")
    return rows.iloc[0].to_dict()


def load_run_config(run_dir: str | Path, record: dict[str, Any]) -> Any:
    """RUN_DIR/config.yaml as an EvaluationConfig, with the record's guidance setting (rho, s) put in."""
    from grits_lab.config import config_from_dict, load_yaml
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.evaluation_config import EvaluationConfig, without_retired_keys
    from grits_lab.evaluation.methods import METHODS, guidance_gap

    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        raise InputError(f"no config.yaml in {run_dir}: replay needs the resolved config `grits-lab evaluate` writes there")
    data = dict(load_yaml(path))
    # Only the replayed method: a run directory may come from someone else, and loading the config
    # imports the controller file of every custom method it lists.
    method = record["method"]
    data["methods"] = [method]
    rho, s = record.get("rho"), record.get("s")
    if method in METHODS and METHODS[method].sampler == "posthoc" and not _is_nan(rho):
        data["posthoc"] = {**data.get("posthoc", {}), "rho": float(rho)}
    try:
        config = config_from_dict(EvaluationConfig, without_retired_keys(data))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if rho is not None and not _is_nan(rho) and guidance_gap(method, config) is None:  # grits*, or a guided registered controller
        config = replace(config, guidance=replace(config.guidance, rho=float(rho), s=int(s)))
    return config


def checked_checkpoints(method: str, config: Any, record: dict[str, Any]) -> dict[str, str]:
    """{key: path} of the method's checkpoints, each checked against the record's digest (StorageError on a mismatch)."""
    from grits_lab.evaluation.methods import file_digest, method_checkpoints

    paths = method_checkpoints(method, config.checkpoints)
    for key, path in paths.items():
        recorded = record.get(f"checkpoint_{key}")
        if recorded is None or _is_nan(recorded):
            continue  # a record written before digests were stored: nothing to check against
        actual = file_digest(path)
        if actual != recorded:
            raise StorageError(f"checkpoint `{key}` at {path} has digest {actual}, but the episode was recorded with {recorded}: "
                               "it was retrained or replaced since; put the recorded file back to replay")
    return paths


def attribution_caption(attribution: dict[str, int]) -> str:
    """One caption line naming where the spilled particles were lost, e.g. "lost: carry, off the moving
    spoon 2 · pour, poured outside the target 1" ("" when nothing is spilled); keys as `attribution_columns`."""
    from grits_lab.report.spill_tables import CAUSE_NAMES
    from grits_lab.sim.spill_metrics import attribution_columns

    columns = attribution_columns()
    parts = [f"{columns[c][0].replace('_', ' ')}, {CAUSE_NAMES[columns[c][1]].lower()} {n}" for c, n in attribution.items() if n]
    return "lost: " + " · ".join(parts) if parts else ""


class _FilmedEnv:
    """A ScoopEnv seen through a camera: renders a captioned frame after the reset and after every action."""

    def __init__(self, env: Any, title: str, camera: Any, every: int) -> None:
        self._env = env
        self._title = title
        self._camera = camera
        self._every = max(1, int(every))
        self.frames: list[np.ndarray] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._env, name)

    def _film(self, info: dict[str, Any]) -> None:
        from grits_lab.sim.video import caption, render_frame

        step = int(info.get("step", 0))
        if step % self._every:
            return
        frame = render_frame(self._env, self._camera)
        lines = [self._title, f"step {step:>3}   {self._env.tracker.stage.replace('_', ' ')}   spilled {int(info.get('spilled', 0))}"]
        # Always three lines: every frame of a video must have the same size.
        lost = attribution_caption(self._env.metrics()["spill_attribution"]) or "lost: nothing"
        self.frames.append(caption(frame, lines + [lost]))

    def reset(self, *args: Any, **kwargs: Any) -> Any:
        obs, info = self._env.reset(*args, **kwargs)
        self._film(info)
        return obs, info

    def step(self, action: Any) -> Any:
        out = self._env.step(action)
        self._film(out[4])
        return out

    def step_along(self, poses: Any) -> Any:
        out = self._env.step_along(poses)
        self._film(out[4])
        return out


class _CountedEnv:
    """An env that calls `tick()` after every action (a progress bar's update)."""

    def __init__(self, env: Any, tick: Callable[[], Any]) -> None:
        self._env, self._tick = env, tick

    def __getattr__(self, name: str) -> Any:
        return getattr(self._env, name)

    def step(self, action: Any) -> Any:
        out = self._env.step(action)
        self._tick()
        return out

    def step_along(self, poses: Any) -> Any:
        out = self._env.step_along(poses)
        self._tick()
        return out


def replay_episode(run_dir: str | Path, *, method: str, food: str, level: str, trial: int, video: str | Path | None = None,
                   camera: Any = None, every: int = 1, plan_figure: str | Path | None = None, plan: int | None = None,
                   progress: bool = False) -> ReplayResult:
    """Re-run one recorded evaluation episode and compare its metrics with the record.

    video: `.mp4` or `.gif` path for a captioned video (None: no rendering at all); camera: a
    `CameraConfig` (default `grits_lab.sim.video.VIDEO_CAMERA`, 480 x 360); every: render every
    k-th action. plan_figure: a `.png` path for the guidance picture of one guided plan (`plan`,
    default the plan guidance moved farthest): the unguided and guided executed chunks from the
    same noise over the composite cloud, with P(spill) of each (grits_lab.report.guidance_effect.plan_figure);
    InputError for a method without guidance. progress: a bar on stderr counting the actions played. Raises InputError (no such record, no config), StorageError (a checkpoint whose
    digest differs from the record's) or ConfigError (a config that no longer loads).
    """
    import torch

    from grits_lab.evaluation.task_episode import run_task_episode
    from grits_lab.evaluation.methods import METHODS, build_controller
    from grits_lab.perception.env_clouds import builder_for_env
    from grits_lab.sim.env import ScoopEnv
    from grits_lab.sim.video import VIDEO_CAMERA, check_video_path, write_video
    from tqdm import tqdm

    if video is not None:
        video = check_video_path(video)
    record = load_record(run_dir, method=method, food=food, level=level, trial=trial)
    config = load_run_config(run_dir, record)
    paths = checked_checkpoints(method, config, record)
    torch.set_num_threads(config.num_threads)
    env = ScoopEnv(config.sim)
    cache: dict[Any, Any] = {}
    rho, s = record.get("rho"), int(record.get("s", -1))
    rho = math.nan if rho is None else float(rho)
    try:
        builder = builder_for_env(config.cloud, env)
        controller = build_controller(method, config, paths, lambda key, factory: cache[key] if key in cache else cache.setdefault(key, factory()))
        if plan_figure is not None:
            if not hasattr(controller, "capture_plans") or METHODS[method].sampler not in ("guided", "posthoc"):
                raise InputError(f"--plan-figure needs a guided method (grits*, dp_post); {method!r} has no guidance to draw")
            controller.capture_plans = True
        seed = int(record["seed"])
        played: Any = env
        if video is not None:
            setting = "" if math.isnan(rho) else f"   rho {rho:g}" + (f" s {s}" if s >= 0 else "")
            title = f"{method}   {food} / {level}   trial {trial}   seed {seed}{setting}"
            played = _FilmedEnv(env, title, camera or VIDEO_CAMERA, every)
        bar = tqdm(desc=f"replaying {method} {food}/{level} trial {trial}", unit="action", disable=not progress, dynamic_ncols=True)
        replayed = run_task_episode(_CountedEnv(played, bar.update) if progress else played, controller, config,
                                    seed=seed, food=food, level=level, builder=builder)
        bar.close()
    finally:
        env.close()
    # A column the record lacks, or holds empty while the replay measured it (a run resumed across
    # the commit that added the column), is reported, not compared.
    unrecorded = {k: v for k, v in replayed.items() if not k.startswith("_") and k not in NOT_COMPARED
                  and (k not in record or (_plain(record[k]) is None and _plain(v) is not None))}
    compared = sorted(k for k in replayed if k in record and k not in NOT_COMPARED and k not in unrecorded)
    mismatches = {k: (record[k], replayed[k]) for k in compared if not _equal(record[k], replayed[k])}
    recorded_kernels = record.get(CPU_KERNELS)
    result = ReplayResult(method, food, str(level), int(trial), int(record["seed"]), rho, s, compared, mismatches,
                          replayed=replayed, unrecorded=unrecorded,
                          recorded_kernels=None if _plain(recorded_kernels) is None else str(recorded_kernels),
                          replayed_kernels=replayed.get(CPU_KERNELS))
    if video is not None:
        result.video = str(write_video(video, played.frames, fps=config.sim.control_hz / played._every))
        result.frames = len(played.frames)
    if plan_figure is not None:
        from grits_lab.report.guidance_effect import plan_figure as draw_plan

        captured = controller.captured
        if not captured:
            raise InputError(f"the replayed {method} episode made no guided plan to draw")
        chosen = max(captured, key=lambda c: c["displacement_mm"]) if plan is None else next((c for c in captured if c["plan"] == plan), None)
        if chosen is None:
            raise InputError(f"--plan {plan}: the episode's guided plans are {[c['plan'] for c in captured]}")
        result.plan_figure = str(draw_plan(chosen, Path(plan_figure), f"{method} {food}/{level} trial {trial}: "))
    return result
