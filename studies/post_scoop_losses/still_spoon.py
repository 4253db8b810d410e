"""A heaped spoon held still: how far its grains move, the measure behind `TransferSettings.solver_iterations`.

A heap on a real spoon held still does not move. `hold_heaped_spoon` builds one (the scripted
expert's nominal scoop, then the spoon lifted 10 cm straight up), holds it still and measures
each grain's displacement in the spoon's frame, with the arm holding the spoon at a given number
of solver iterations or with the spoon made static (the arm's constraint removed, the spoon's
mass set to zero), which isolates the arm-spoon chain. docs/evaluation.md, "Grains a still spoon
loses", gives the measurement; studies/post_scoop_losses/still_spoon_figure.py draws it for several foods.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from grits_lab.sim.env import ScoopEnv
from grits_lab.sim.expert import nominal_expert_trajectory
from grits_lab.sim.sim_config import SimConfig
from grits_lab.sim.spill_metrics import in_spoon_frame

LIFT_ACTIONS = 10  # 1 cm per action, straight up, keeping the scoop's last orientation
SETTLE_ACTIONS = 20  # the lifted spoon held still before the watch starts


def hold_heaped_spoon(food: str, level: str, seed: int, *, iterations: int | None = None,
                      holder: Literal["arm", "static"] = "arm", hold_actions: int = 40,
                      config: SimConfig | None = None) -> dict[str, np.ndarray | int]:
    """Scoop `food` at `level` (seed) with the nominal expert, lift the spoon 10 cm, hold it still
    for SETTLE_ACTIONS actions, then watch it for `hold_actions` more (0.1 s each) at `iterations`
    solver iterations (None: the config's) held by the arm, or made static (`holder: static`).

    Returns "moved" (N,) metres each grain that was on or over the spoon when the watch started
    moved in the spoon's frame by its end (a grain that left the spoon moved centimetres),
    "scooped" and "above_spoon_rim" (ScoopEnv.metrics at the watch's start). ValueError for an
    unknown holder; InputError for a food or level the library lacks.
    """
    if holder not in ("arm", "static"):
        raise ValueError(f"holder must be arm or static, got {holder!r}")
    env = ScoopEnv(config or SimConfig())
    try:
        env.reset(seed=seed, options={"food": food, "level": level})
        action = None
        for action in nominal_expert_trajectory(env.scene(), env.config.control_hz):
            env.step(action)
        lifted = np.array(action, dtype=np.float64)
        for k in range(1, LIFT_ACTIONS + 1):
            lifted = np.array(action, dtype=np.float64)
            lifted[2] += 0.01 * k
            env.step(lifted)
        for _ in range(SETTLE_ACTIONS):
            env.step(lifted)
        world, spoon = env.world, env.spoon_geometry

        def grains() -> np.ndarray:
            return in_spoon_frame(world.particle_positions(), world.spoon_matrix())

        start = grains()
        near = (np.abs(start[:, 0]) < spoon.half_length + 0.012) & (np.abs(start[:, 1]) < spoon.half_width + 0.012) & \
            (start[:, 2] > -0.01) & (start[:, 2] < 0.05)
        metrics = env.metrics()
        env.set_solver_iterations(iterations)
        if holder == "static":
            client = world.client
            for i in reversed(range(client.getNumConstraints())):
                client.removeConstraint(client.getConstraintUniqueId(i))
            client.changeDynamics(world.spoon, -1, mass=0.0)
            client.resetBaseVelocity(world.spoon, [0, 0, 0], [0, 0, 0])
        for _ in range(hold_actions):
            env.step(lifted)
        return {"moved": np.linalg.norm(grains()[near] - start[near], axis=1),
                "scooped": int(metrics["scooped"]), "above_spoon_rim": int(metrics["above_spoon_rim"])}
    finally:
        env.close()
