"""A plain torch policy evaluated as a grits_lab method, without editing the package.

The policy is any `torch.nn.Module` mapping the spoon's newest pose and the source bowl's centre
(12 numbers) to the next `n_action_steps` moves of the spoon (n_action_steps x 3, metres after a
tanh times `max_step`). `TorchPolicyController` adapts it to the controller protocol
(grits_lab/policies/control.py): it keeps the spoon's orientation, plans a chunk per call and ends
the scoop after `max_plans` chunks. Register it in an evaluation config:

    methods: [torch_mlp]
    custom_methods:
      torch_mlp:
        controller: examples/torch_controller.py:TorchPolicyController
        options: {weights: null, hidden: 64, seed: 0}   # weights: a state_dict saved with torch.save

`weights: null` keeps the seeded random initialisation (what the test evaluates end to end).

`GuidedTorchPolicyController` is the same policy with two parameters a sweep can tune: its class
takes keyword arguments `rho` and `s`, so grits_lab builds it with the evaluation config's
`guidance.rho` / `guidance.s` (a sweep trial's values), records them, and `grits-lab sweep` can
name it in `evaluation.method`. It is not GRITS (no diffusion, no spillage predictor, no gradient):
after the policy plans a chunk, its last `s` actions are pulled horizontally toward the source
bowl's vertical axis by `rho * max_step` metres each (never past the axis): rho = 0 or s = 0 gives
exactly TorchPolicyController's chunk, s >= n_action_steps corrects all of it. A fixed heuristic,
whether it helps is what a sweep measures. Register it with the same options as
TorchPolicyController; `rho` and `s` come from `guidance`, not from `options`:

    custom_methods:
      torch_mlp_guided:
        controller: examples/torch_controller.py:GuidedTorchPolicyController
        options: {weights: null, hidden: 64, seed: 0}
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from grits_lab.policies.control import Chunk


def mlp_policy(hidden: int, n_action_steps: int) -> nn.Module:
    """(B, 12) spoon pose (9) + bowl centre (3) -> (B, n_action_steps * 3) raw moves."""
    return nn.Sequential(nn.Linear(12, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 3 * n_action_steps))


class TorchPolicyController:
    """The controller protocol around a torch policy; see the module docstring."""

    cloud_steps = 0  # reads no point cloud
    image_steps = 0

    def __init__(self, weights: str | None = None, hidden: int = 64, n_action_steps: int = 8, max_plans: int = 4,
                 max_step: float = 0.008, seed: int = 0) -> None:
        torch.manual_seed(seed)
        self.policy = mlp_policy(hidden, n_action_steps)
        if weights is not None:
            self.policy.load_state_dict(torch.load(weights, map_location="cpu", weights_only=True))
        self.policy.eval()
        self.n_action_steps = n_action_steps
        self.max_plans = max_plans
        self.max_step = max_step
        self.plans = 0

    def reset(self, scene: Any) -> None:
        self.plans = 0

    @torch.no_grad()
    def plan(self, history: Any, scene: Any) -> Chunk | None:
        if self.plans >= self.max_plans:
            return None
        self.plans += 1
        pose = np.asarray(history.ee_pose[-1], dtype=np.float32)
        bowl = np.asarray(scene.source_bowl_position(), dtype=np.float32)
        moves = self.policy(torch.from_numpy(np.concatenate([pose, bowl]))[None])
        steps = (self.max_step * torch.tanh(moves)).reshape(self.n_action_steps, 3).numpy()
        actions = np.repeat(pose[None], self.n_action_steps, axis=0)
        actions[:, :3] = pose[:3] + np.cumsum(steps, axis=0)
        return Chunk(actions.astype(np.float32), {"plan": self.plans})


class GuidedTorchPolicyController(TorchPolicyController):
    """TorchPolicyController plus a "stay over the bowl" correction of strength `rho` on the last `s`
    actions of each chunk; see the module docstring. rho = 0 or s <= 0 leaves every chunk exactly
    as TorchPolicyController plans it."""

    def __init__(self, rho: float, s: int, **options: Any) -> None:
        super().__init__(**options)
        self.rho = float(rho)
        self.s = int(s)

    def plan(self, history: Any, scene: Any) -> Chunk | None:
        chunk = super().plan(history, scene)
        if chunk is None:
            return None
        actions = chunk.actions.copy()
        first = len(actions) - min(max(self.s, 0), len(actions))  # the first corrected action
        pull = np.zeros(len(actions))  # metres each action moved
        if self.rho > 0 and first < len(actions):
            axis = np.asarray(scene.source_bowl_position(), dtype=np.float64)[:2]
            tail = actions[first:, :2].astype(np.float64)
            offset = axis - tail  # (s, 2) horizontal way to the bowl's axis
            distance = np.linalg.norm(offset, axis=1)
            pull[first:] = np.minimum(distance, self.rho * self.max_step)
            actions[first:, :2] = tail + offset * (pull[first:] / np.maximum(distance, 1e-12))[:, None]
        return Chunk(actions.astype(np.float32), {**chunk.diagnostics, "correction_mm": float(1000.0 * pull.mean())})
