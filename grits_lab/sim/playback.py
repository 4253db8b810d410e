"""Playing whole trajectories: input validation, `play_trajectory`, `play_episode` and the `EpisodeRecord`."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from grits_lab.errors import InputError
from grits_lab.geometry import pose7_to_pose9
from grits_lab.seeding import derive_seed, make_rng
from grits_lab.versions import PROTOCOL


@dataclass
class EpisodeRecord:
    """Outcome of one scooping episode, every number measured from particle states."""

    food: str
    split: str
    quantity: str
    seed: int
    n_particles: int
    spilled: int  # particles spilled (left the source bowl, not in the spoon or target bowl)
    scooped: int  # particles lifted in the spoon above the rim at the end
    spoon_coverage: float  # fraction of the spoon floor covered by the scooped particles
    scoop_success: bool
    scoop_failure: bool
    spillage: bool
    first_spill_step: int  # action step at which spillage first happened, -1 if none
    ik_failures: int  # action steps whose target pose the arm could not reach
    n_steps: int
    protocol: str = PROTOCOL  # the task protocol the episode ran under (grits_lab/versions.py, docs/protocol.md)
    transferred: int = -1  # particles in the target bowl (-1: no transfer stage played)
    settle_time_s: float = 0.0
    wall_time_s: float = 0.0
    target_bowl_xy: list[float] = field(default_factory=list)
    spilled_over_time: list[int] = field(default_factory=list)  # spilled count after each action
    # Spilled particles by stage and cause, `spilled_<stage>_<cause>` (grits_lab.sim.spill_metrics.SpillTracker).
    spill_attribution: dict[str, int] = field(default_factory=dict)
    particle_parameters: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def summary(self) -> dict[str, Any]:
        """The scalar fields (no per-step lists), with the spill attribution flattened to `spilled_<stage>_<cause>`."""
        out = {k: v for k, v in self.to_dict().items() if not isinstance(v, (list, dict))}
        out.update(self.spill_attribution)
        return out


def validate_trajectory(array: Any, source: str = "trajectory") -> np.ndarray:
    """(T, 9) float64 from a (T, 9) xyz + 6-D rotation or (T, 7) xyz + quaternion xyzw array."""
    a = np.asarray(array)
    if a.ndim != 2 or a.shape[1] not in (7, 9) or a.shape[0] < 1:
        raise InputError(f"{source}: expected an array of shape (T, 9) or (T, 7), got {a.shape}")
    if not np.issubdtype(a.dtype, np.number):
        raise InputError(f"{source}: expected numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        bad = int(np.argwhere(~np.isfinite(a))[0, 0])
        raise InputError(f"{source}: contains NaN or infinite values (first at row {bad})")
    if a.shape[1] == 7:
        q = a[:, 3:7]
        if np.any(np.linalg.norm(q, axis=1) < 1e-6):
            raise InputError(f"{source}: a quaternion has zero length")
        return pose7_to_pose9(a)
    r = a[:, 3:9]
    if np.any(np.linalg.norm(r[:, :3], axis=1) < 1e-6) or np.any(np.linalg.norm(np.cross(r[:, :3], r[:, 3:]), axis=1) < 1e-6):
        raise InputError(f"{source}: a 6-D rotation has degenerate (zero or parallel) columns")
    return a


def load_trajectory(path: str | Path) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"trajectory file not found: {path}")
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise InputError(f"{path}: not a readable .npy array ({exc})") from None
    if not isinstance(array, np.ndarray):
        raise InputError(f"{path}: expected a single .npy array")
    return validate_trajectory(array, str(path))


StepCallback = Callable[[int, Any, dict], None]


def play_trajectory(env: Any, trajectory: np.ndarray, on_step: StepCallback | None = None) -> EpisodeRecord:
    """Execute every row of `trajectory` (T, 9 or 7) in the already reset `env`; return the record.

    `on_step(t, env, obs)` runs before action t is applied (and once more with t = T after the
    last one), e.g. to render cameras or store point clouds.
    """
    traj = validate_trajectory(trajectory)
    start = time.perf_counter()
    obs = env._obs()
    for t, action in enumerate(traj):
        if on_step is not None:
            on_step(t, env, obs)
        obs, _, _, truncated, _ = env.step(action)
        if truncated:
            break
    if on_step is not None:
        on_step(len(traj), env, obs)
    return make_record(env, wall_time_s=time.perf_counter() - start)


def make_record(env: Any, wall_time_s: float = 0.0, transferred: int = -1) -> EpisodeRecord:
    m = env.metrics()
    return EpisodeRecord(
        food=env.food_name, split=env.food.split, quantity=env.level, seed=env.seed, n_particles=m["n_particles"],
        spilled=m["spilled"], scooped=m["scooped"], spoon_coverage=round(m["spoon_coverage"], 4),
        scoop_success=m["scoop_success"], scoop_failure=m["scoop_failure"], spillage=m["spillage"],
        first_spill_step=m["first_spill_step"], ik_failures=m["ik_failures"], n_steps=env.step_count,
        transferred=transferred, settle_time_s=env.world.settle_time_s, wall_time_s=round(wall_time_s, 3),
        target_bowl_xy=[round(float(v), 5) for v in env.world.target_bowl_position[:2]],
        spilled_over_time=list(env.tracker.history), spill_attribution=m["spill_attribution"],
        particle_parameters=env.particle_parameters(),
    )


def play_episode(env: Any, food: str, level: str, seed: int, trajectory: np.ndarray | None = None,
                on_step: StepCallback | None = None) -> tuple[EpisodeRecord, np.ndarray]:
    """Reset to (food, level, seed) and play `trajectory`, or the seeded randomized expert when None.

    Returns the record and the played (T, 9) trajectory. The expert's randomness comes from
    derive_seed(seed, "expert"), so the world and the expert can be varied independently.
    """
    from grits_lab.sim.expert import expert_trajectory

    env.reset(seed=seed, options={"food": food, "level": level})
    if trajectory is None:
        trajectory = expert_trajectory(env.scene(), make_rng(derive_seed(seed, "expert")), env.config.control_hz)
    traj = validate_trajectory(trajectory)
    return play_trajectory(env, traj, on_step=on_step), traj
