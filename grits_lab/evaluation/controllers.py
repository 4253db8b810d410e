"""The learned methods' scoop controllers (dp, dp_post, the GRITS variants, bc), the scripted expert's, and the episode's observation history.

They follow the controller protocol of grits_lab/policies/control.py, as the baselines in
grits_lab/policies do. `scene` (grits_lab/evaluation/episode_scene.py) gives read access to the cameras
and the spoon's sensors; `history` holds the measured spoon poses and clouds so far.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
import torch

from grits_lab.policies.control import Chunk, is_still
from grits_lab.sampling.guidance import DDIMSampler, GuidanceConfig, PostHocConfig, PostHocSampler
from grits_lab.seeding import derive_seed

if TYPE_CHECKING:  # annotations only
    from grits_lab.evaluation.episode_scene import EpisodeScene

__all__ = ["BCController", "Chunk", "DiffusionController", "ExpertController", "LearnedController", "ObsHistory", "is_still"]


class ObsHistory:
    """Measured spoon poses (every step), commanded actions and clouds (where rendered) of the current episode."""

    def __init__(self) -> None:
        self.ee_pose: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []  # actions[i] took the spoon from ee_pose[i] to ee_pose[i + 1]
        self.clouds: dict[int, np.ndarray] = {}
        self.rgbd: dict[int, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.ee_pose)

    def append(self, obs: dict[str, Any], action: np.ndarray | None = None) -> None:
        """The observation after `action` (None for the first observation of the episode)."""
        if action is not None:
            self.actions.append(np.asarray(action, dtype=np.float32))
        self.ee_pose.append(np.asarray(obs["ee_pose"], dtype=np.float32))

    def past_actions(self, k: int) -> np.ndarray:
        """(k, 9) the newest commanded actions; before the first, the first measured pose (the spoon at rest), as in training."""
        rest = self.ee_pose[0]
        out = [self.actions[i] if i >= 0 else rest for i in range(len(self.actions) - k, len(self.actions))]
        return np.stack(out) if out else np.zeros((0, 9), dtype=np.float32)

    def poses(self, n: int) -> np.ndarray:
        """(n, 9) newest poses; before the first step the first pose repeats (robot at rest), as in training."""
        idx = np.clip(np.arange(len(self) - n, len(self)), 0, len(self) - 1)
        return np.stack([self.ee_pose[i] for i in idx])

    def stacked(self, store: dict[int, np.ndarray], n: int) -> np.ndarray:
        """(n, ...) newest entries of a sparse per-step store; a missing step takes the nearest earlier one
        (or the earliest stored), which only fills history slots the policy does not read."""
        steps = sorted(store)
        out = []
        for i in np.clip(np.arange(len(self) - n, len(self)), 0, len(self) - 1):
            earlier = [s for s in steps if s <= i]
            out.append(store[earlier[-1] if earlier else steps[0]])
        return np.stack(out)


class LearnedController:
    """What the learned policies' controllers share: the sensors the policy reads, and its observation.

    The observation is built from the policy's own `obs_keys`, so a policy that reads one more key
    (say `past_action`) is served without a change here.
    """

    stops_when_still = True

    def __init__(self, policy: Any) -> None:
        self.policy = policy
        cfg = policy.config
        self.n_obs_steps = cfg.n_obs_steps
        kind = cfg.obs_encoder.kind
        self.cloud_steps = cfg.obs_encoder.cloud_steps if kind == "pointcloud" else 0
        self.image_steps = cfg.n_obs_steps if kind == "rgbd" else 0

    def observation(self, history: ObsHistory) -> dict[str, np.ndarray]:
        n = self.n_obs_steps
        sources = {
            "ee_pose": lambda: history.poses(n),
            "cloud": lambda: history.stacked(history.clouds, n),
            "rgbd": lambda: history.stacked(history.rgbd, n),
            "past_action": lambda: history.past_actions(n - 1),
        }
        return {key: sources[key]() for key in self.policy.obs_keys}


class DiffusionController(LearnedController):
    """dp, dp_post and the GRITS variants: one trained policy, a sampler, optionally a predictor.

    Each plan draws its initial noise from a generator seeded by (episode seed, plan index), so
    dp and grits with rho = 0 see the very same noise and produce the very same episode;
    `noise_keys(plan)` gives those keys (a `ScoopHook`'s, grits_lab/policies/control.py: a study may branch one plan).
    """

    def __init__(self, policy: Any, predictor: Any, sampler_kind: str, guidance: GuidanceConfig | None, posthoc: PostHocConfig | None,
                 raw_cloud: bool = False, noise_keys: Callable[[int], tuple[object, ...]] | None = None) -> None:
        super().__init__(policy)
        self.predictor = predictor
        self.raw_cloud = raw_cloud
        self.noise_keys = noise_keys or (lambda plan: ("plan", plan))
        self.n_action_steps = policy.config.n_action_steps
        scheduler = policy.noise_scheduler
        if sampler_kind == "guided":
            self.sampler = DDIMSampler(scheduler, guidance)
        elif sampler_kind == "posthoc":
            self.sampler = PostHocSampler(scheduler, posthoc)
        else:
            self.sampler = policy.sampler
        self.plans = 0
        self.seed = 0
        # With `capture_plans`, every guided plan keeps what a guidance picture needs (`captured`).
        self.capture_plans = False
        self.captured: list[dict[str, Any]] = []

    def reset(self, scene: EpisodeScene) -> None:
        self.plans = 0
        self.seed = scene.seed
        self.captured = []

    def plan(self, history: ObsHistory, scene: EpisodeScene) -> Chunk:
        from grits_lab.spillage import SpillageObjective

        start = time.perf_counter()
        obs = self.observation(history)
        objective = None
        if self.predictor is not None:
            cloud = scene.cloud_raw() if self.raw_cloud else scene.cloud()
            objective = SpillageObjective(self.predictor, cloud, self.policy.action_normalizer, self.n_obs_steps, self.n_action_steps)
        generator = torch.Generator().manual_seed(derive_seed(self.seed, *self.noise_keys(self.plans)))
        with torch.inference_mode(False):
            plan = self.policy.plan(obs, sampler=self.sampler, objective=objective, generator=generator)
        self.plans += 1
        diagnostics = plan.result.summary()
        unguided = None
        if plan.result.unguided is not None:
            unguided = self.executed_chunk(plan.result.unguided)
            guided = self.executed_chunk(plan.result.sample)
            diagnostics["displacement_mm"] = float(1000.0 * np.linalg.norm(unguided[:, :3] - guided[:, :3], axis=1).mean())
            if self.capture_plans:
                self.captured.append({
                    "plan": self.plans - 1, "cloud": np.asarray(cloud, dtype=np.float32),
                    "unguided": unguided[:, :3], "guided": guided[:, :3],
                    "p_spill_unguided": diagnostics["p_spill_unguided"], "p_spill_guided": diagnostics["p_spill_guided"],
                    "displacement_mm": diagnostics["displacement_mm"],
                })
        return Chunk(plan.actions[0], diagnostics, time.perf_counter() - start,
                     unguided_actions=None if unguided is None else unguided.astype(np.float32))

    def executed_chunk(self, sample: torch.Tensor) -> np.ndarray:
        """(n_action_steps, 9) world-frame poses of the executed chunk of a normalized sample (first in batch), float64."""
        start = self.policy.config.action_start
        chunk = sample[:1, start : start + self.n_action_steps].detach().double()
        return self.policy.action_normalizer.unnormalize(chunk)[0].cpu().numpy()


class BCController(LearnedController):
    """Behavior cloning: one deterministic regression of the next chunk per plan."""

    def reset(self, scene: EpisodeScene) -> None:
        pass

    def plan(self, history: ObsHistory, scene: EpisodeScene) -> Chunk:
        start = time.perf_counter()
        actions = self.policy.predict_action(self.observation(history))
        return Chunk(actions, {}, time.perf_counter() - start)


class ExpertController:
    """The scripted expert's scoop, the demonstrations' own (grits_lab/sim/expert.py), randomized from
    the episode's seed exactly as `grits-lab collect` draws a demonstration's: an oracle scoop for
    measuring the stages after it (experiments/oracle_transfer.yaml). Plays it whole, then done."""

    cloud_steps = 0
    image_steps = 0

    def __init__(self) -> None:
        self.done = False

    def reset(self, scene: EpisodeScene) -> None:
        self.done = False

    def plan(self, history: ObsHistory, scene: EpisodeScene) -> Chunk | None:
        from grits_lab.seeding import make_rng
        from grits_lab.sim.expert import expert_trajectory

        if self.done:
            return None
        self.done = True
        env = scene.env
        actions = expert_trajectory(env.scene(), make_rng(derive_seed(scene.seed, "expert")), env.config.control_hz)
        return Chunk(actions=np.asarray(actions, dtype=np.float32))
