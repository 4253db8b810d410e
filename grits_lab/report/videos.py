"""Episodes to watch: which recorded episodes the report replays per food, and the section that shows them.

The rule (`choose_episodes`), per food, over the episodes (level, trial, seed) recorded for both
methods of the pair (default Diffusion Policy and GRITS, which see the same seeds):

1. DP spilled and GRITS did not (what guidance is for);
2. both spilled;
3. GRITS spilled and DP did not;
4. neither spilled;

ties broken by level (low, medium, high) and trial; the first `per_food` seeds are taken and
each is replayed under both methods, shown side by side. A food recorded for only one of the
methods takes that method's episodes, spilled first. Errored episodes are never chosen.

Replaying needs the simulator and the checkpoints; the report hands that work in as a callable
(`replay`, `grits_lab.report.replay.replay_episode` from the command), so this module and a
plain `grits-lab report` need neither.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from grits_lab.errors import GritsError
from grits_lab.report.vocabulary import LEVEL_ORDER, PER_FOOD_METHODS, UNSEEN_FOODS, food_display, method_display, ordered

RANK_REASONS = ("{a} spilled, {b} did not", "both spilled", "{b} spilled, {a} did not", "neither spilled")


@dataclass
class VideoPick:
    """One episode (food, level, trial, seed) to replay under each of `methods`, and why it was chosen."""

    food: str
    level: str
    trial: int
    seed: int
    methods: list[str]
    reason: str


@dataclass
class EpisodeVideo:
    """One replayed episode in the report: `path` relative to the report folder (None if the replay failed)."""

    method: str
    path: str | None
    caption: str


@dataclass
class VideoRow:
    """Videos of one seed under each method, shown side by side."""

    title: str
    videos: list[EpisodeVideo] = field(default_factory=list)


def choose_episodes(episodes: pd.DataFrame, per_food: int, methods: tuple[str, str] = PER_FOOD_METHODS) -> list[VideoPick]:
    """Up to `per_food` episodes per food by the module's rule; `episodes` are normalized records (report.loading)."""
    if per_food < 1 or episodes is None or episodes.empty:
        return []
    a, b = methods
    usable = episodes[~episodes["is_error"] & episodes["method"].isin(methods)]
    picks = []
    for food in ordered(usable["food"].unique(), UNSEEN_FOODS):
        rows = usable[usable["food"] == food]
        by_method = {m: rows[rows["method"] == m].drop_duplicates(["level", "trial", "seed"]).set_index(["level", "trial", "seed"])
                     for m in methods}
        keys = set(by_method[a].index) & set(by_method[b].index)
        present = [m for m in methods if len(by_method[m])]
        if keys:
            chosen_methods = list(methods)
        else:
            chosen_methods = present[:1]
            keys = set(by_method[present[0]].index)
        ranked = []
        for key in keys:
            if len(chosen_methods) == 2:
                sa, sb = bool(by_method[a].loc[key, "spillage"]), bool(by_method[b].loc[key, "spillage"])
                rank = 0 if sa and not sb else 1 if sa and sb else 2 if sb else 3
                reason = RANK_REASONS[rank].format(a=method_display(a), b=method_display(b))
            else:
                spilled = bool(by_method[chosen_methods[0]].loc[key, "spillage"])
                rank, reason = (0, "spilled") if spilled else (1, "did not spill")
                reason = f"{method_display(chosen_methods[0])} {reason} (the only method recorded on this food)"
            level, trial, seed = key
            level_rank = LEVEL_ORDER.index(level) if level in LEVEL_ORDER else len(LEVEL_ORDER)
            ranked.append(((rank, level_rank, str(level), int(trial)), VideoPick(food, str(level), int(trial), int(seed), chosen_methods, reason)))
        picks += [pick for _, pick in sorted(ranked, key=lambda item: item[0])[:per_food]]
    return picks


def film_picks(run_dir: str | Path, picks: list[VideoPick], replay: Callable[..., Any], out_dir: Path,
               suffix: str = ".mp4", progress: bool = False) -> list[VideoRow]:
    """Replay every pick under each of its methods into OUT/videos/; a replay that fails is shown with its error.

    progress: a tqdm bar on stderr, one tick per video (each takes tens of seconds).
    """
    from tqdm import tqdm

    rows = []
    bar = tqdm(total=sum(len(p.methods) for p in picks), desc="replaying episodes", unit="video",
               disable=not progress, dynamic_ncols=True)
    for pick in picks:
        row = VideoRow(f"{food_display(pick.food, long=True)} / {pick.level}, trial {pick.trial} (seed {pick.seed}): {pick.reason}")
        for method in pick.methods:
            relative = f"videos/{pick.food}-{pick.level}-{pick.trial}-{method}{suffix}"
            bar.set_postfix_str(f"{method} {pick.food}/{pick.level} trial {pick.trial}")
            try:
                result = replay(run_dir, method=method, food=pick.food, level=pick.level, trial=pick.trial, video=out_dir / relative)
            except GritsError as exc:
                row.videos.append(EpisodeVideo(method, None, f"{method_display(method)}: not replayed: {exc}"))
                continue
            finally:
                bar.update()
            row.videos.append(EpisodeVideo(method, relative, f"{method_display(method)}: {_outcome(result.replayed)}. {result.describe()}"))
        rows.append(row)
    bar.close()
    return rows


def _outcome(record: dict[str, Any]) -> str:
    words = ["task success" if record.get("task_success") else "task failure"]
    words.append(f"spilled {record.get('spilled_total', record.get('spilled'))}")
    words.append("scooped" if record.get("scoop_success") else "scoop failure")
    return ", ".join(words)
