"""A synthetic stand-in for the GRITS evaluation: fast, deterministic records from (rho, s).

NOT GRITS AND NOT SIMULATION. It exists so that the sweep machinery (storage, resumption,
several workers, outputs) can be exercised in seconds. Its records are labelled
`method = "synthetic"` and `protocol = "synthetic"`. The response surface mimics the trade-off
the paper reports: stronger guidance (larger rho, more guided denoising steps) lowers spillage
but, pushed too far, raises scoop failures. Each episode draws its outcomes from its own seed,
with the same random numbers for every (rho, s): trials are compared on common random numbers,
as real trials are compared on the same episodes.
"""

from __future__ import annotations

import math
import time

import pandas as pd

from grits_lab.evaluation.grid import EpisodeKey
from grits_lab.seeding import derive_seed, make_rng
from grits_lab.tune.study_config import SyntheticConfig

# The evaluation's DDIM schedule (paper: 16 denoising steps over T = 100 training steps).
_DDIM_STEPS = 16


def guided_steps(s: int, train_timesteps: int, ddim_steps: int = _DDIM_STEPS) -> int:
    """How many DDIM steps have training-step index k <= s (paper: s = 30 -> the last 6 of 16)."""
    stride = train_timesteps // ddim_steps
    return sum(1 for i in range(ddim_steps) if i * stride <= s)


def episode_probabilities(rho: float, s: int, food: str, level: str, train_timesteps: int) -> tuple[float, float]:
    """(P(spill), P(scoop failure)) of one episode under guidance (rho, s)."""
    difficulty = derive_seed(0, "synthetic-food", food) / 0x7FFFFFFF  # in [0, 1)
    base_spill = 0.25 + 0.35 * difficulty + (0.15 if level == "high" else 0.0)
    strength = rho * guided_steps(s, train_timesteps) / 6.0
    p_spill = base_spill * math.exp(-0.35 * strength)
    p_fail = 0.08 + 0.6 * (1.0 - math.exp(-0.02 * strength**2)) * (1.0 + 0.5 * difficulty)
    return p_spill, min(p_fail, 0.95)


class SyntheticEvaluator:
    """`EpisodeEvaluator` returning synthetic records; see the module docstring."""

    label = "synthetic stand-in (not GRITS)"

    def __init__(self, episodes: list[EpisodeKey], config: SyntheticConfig, train_timesteps: int) -> None:
        self.episodes = episodes
        self.config = config
        self.train_timesteps = train_timesteps

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame:
        if self.config.crash_above_rho is not None and rho > self.config.crash_above_rho:
            raise RuntimeError(f"synthetic stand-in: configured crash for rho {rho:.3f} > {self.config.crash_above_rho}")
        rows = []
        for ep in self.episodes:
            start = time.perf_counter()
            if self.config.seconds_per_episode:
                time.sleep(self.config.seconds_per_episode)
            p_spill, p_fail = episode_probabilities(rho, s, ep.food, ep.level, self.train_timesteps)
            u = make_rng(derive_seed(ep.seed, "synthetic")).random(4)
            spill = bool(u[0] < p_spill)
            fail = bool(u[1] < p_fail)
            n_particles = 160
            spilled = 1 + int(u[2] * 20) if spill else 0
            scooped = 0 if fail else 20 + int(u[3] * 30)
            rows.append({
                "run_id": run_id, "protocol": "synthetic", "method": "synthetic", "food": ep.food, "split": "train",
                "level": ep.level, "trial": ep.trial, "seed": ep.seed,
                "task_success": not spill and not fail, "spillage": spill, "scoop_failure": fail,
                "scoop_success": not fail, "spilled_before_scoop": spill and u[2] < 0.7,
                "n_particles": n_particles, "spilled": spilled, "scooped": scooped,
                "transferred": scooped if not spill and not fail else 0,
                "rho": float(rho), "s": int(s), "error": "",
                "wall_time_s": time.perf_counter() - start,
            })
        return pd.DataFrame(rows)

    def reference(self, method: str, run_id: str) -> pd.DataFrame:
        """The stand-in without guidance (rho = 0), labelled `method`: as unguided as it gets."""
        records = self(0.0, 0, run_id)  # rho = 0: no guidance at any s
        return records.assign(method=method, rho=float("nan"), s=-1)

    def close(self) -> None:
        pass
