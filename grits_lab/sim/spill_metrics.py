"""Episode metrics from particle states: where each particle is (source bowl, spoon, target bowl, spilled).

Definitions (all from particle centres, world frame):
- in spoon: inside the spoon bowl's elliptical footprint (widened by its slanted rim) and between
  its floor and 4 cm above it, in the spoon frame.
- in target bowl: inside the target bowl's rim cylinder, below its rim plus 3 cm.
- outside the source bowl: beyond the source bowl's outer rim radius, or below its rim and
  beyond the outer face of its slanted wall (e.g. on the table under the rim's overhang).
- spilled: outside the source bowl and neither in the spoon nor in the target bowl. A particle
  counted as spilled stays spilled (it lies on the table) unless it ends in the target bowl;
  particles above the source bowl (falling back from the spoon) are not spilled.
- scooped: in the spoon and above the source bowl's rim (lifted out of the food).
- spoon coverage: the fraction of the spoon bowl's elliptical floor covered by the footprints
  (discs of each particle's footprint radius) of the scooped particles, projected on the spoon
  floor and rasterized on a 1 mm grid; stacked particles are counted once. The paper's rule: a
  scoop succeeds if it lifts one large item, or covers one third of the spoon (small particles).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grits_lab.sim.shapes import BowlGeometry, SpoonGeometry

SPOON_RIM_MARGIN = 0.009  # the rim wall leans out ~7 mm beyond the floor ellipse
SPOON_MAX_HEIGHT = 0.04
COVERAGE_THRESHOLD = 1.0 / 3.0
_GRID = 0.001


@dataclass
class ParticleCounts:
    """Per-particle classification at one instant."""

    in_spoon: np.ndarray  # (N,) bool
    in_target: np.ndarray
    outside_source: np.ndarray
    lifted: np.ndarray  # in the spoon and above the source bowl's rim
    in_source: np.ndarray  # inside the source bowl: within its outer rim radius, below its rim
    # Outside the spoon's volume but held by it through contacts (`World.carried_by_spoon`): the
    # overhang of a heap. None: not looked up (nothing was outside the spoon and both bowls).
    carried: np.ndarray | None = None


def in_spoon_frame(positions: np.ndarray, spoon_pose: np.ndarray) -> np.ndarray:
    """(N, 3) world points `positions` expressed in the spoon frame of the (4, 4) `spoon_pose`."""
    return (positions - spoon_pose[:3, 3]) @ spoon_pose[:3, :3]


def in_spoon_mask(positions: np.ndarray, spoon_pose: np.ndarray, spoon: SpoonGeometry) -> np.ndarray:
    local = in_spoon_frame(positions, spoon_pose)
    a = spoon.half_length + SPOON_RIM_MARGIN
    b = spoon.half_width + SPOON_RIM_MARGIN
    inside = (local[:, 0] / a) ** 2 + (local[:, 1] / b) ** 2 <= 1.0
    return inside & (local[:, 2] > 0.0) & (local[:, 2] < SPOON_MAX_HEIGHT)


def above_spoon_rim(positions: np.ndarray, spoon_pose: np.ndarray, spoon: SpoonGeometry) -> np.ndarray:
    """(N,) particles whose centre is higher above the spoon's floor than its rim: the heap a
    loaded spoon carries above its rim, which a carry can shed."""
    local = in_spoon_frame(positions, spoon_pose)
    return local[:, 2] > spoon.rim_height


def in_bowl_cylinder(positions: np.ndarray, bowl_position: np.ndarray, bowl: BowlGeometry, above: float) -> np.ndarray:
    d = positions - bowl_position
    r = np.linalg.norm(d[:, :2], axis=1)
    return (r < bowl.outer_radius) & (d[:, 2] < bowl.depth + above) & (d[:, 2] > -0.01)


def outside_bowl(positions: np.ndarray, bowl_position: np.ndarray, bowl: BowlGeometry) -> np.ndarray:
    d = positions - bowl_position
    r = np.linalg.norm(d[:, :2], axis=1)
    wall_outer = bowl.inner_radius_at(d[:, 2]) + bowl.wall_thickness / np.cos(bowl.slant_angle) + 0.002
    return (r > bowl.outer_radius + 0.003) | ((d[:, 2] < bowl.depth) & (r > wall_outer)) | (d[:, 2] < -0.01)


def classify(positions: np.ndarray, spoon_pose: np.ndarray, source_position: np.ndarray, target_position: np.ndarray,
             source: BowlGeometry, target: BowlGeometry, spoon: SpoonGeometry) -> ParticleCounts:
    in_spoon = in_spoon_mask(positions, spoon_pose, spoon)
    lifted = in_spoon & (positions[:, 2] > source_position[2] + source.depth)
    return ParticleCounts(
        in_spoon=in_spoon,
        in_target=in_bowl_cylinder(positions, target_position, target, above=0.03),
        outside_source=outside_bowl(positions, source_position, source),
        lifted=lifted,
        in_source=in_bowl_cylinder(positions, source_position, source, above=0.0),
    )


def fill_height(positions: np.ndarray, tops: np.ndarray, bowl_position: np.ndarray, bowl: BowlGeometry,
                percentile: float = 90.0) -> float:
    """Height of the food in a bowl (m): the `percentile` of particle tops above the inner floor.

    positions: (N, 3) particle centres (world); tops: (N,) height of each particle's top above its
    centre (its vertical half extent, resting). Only particles inside the bowl's rim cylinder count.
    """
    d = positions - bowl_position
    inside = np.linalg.norm(d[:, :2], axis=1) < bowl.rim_radius
    if not inside.any():
        return 0.0
    heights = d[inside, 2] + tops[inside] - bowl.floor_thickness
    return float(np.percentile(heights, percentile))


def spoon_coverage(positions: np.ndarray, radii: np.ndarray, spoon_pose: np.ndarray, spoon: SpoonGeometry) -> float:
    """Fraction of the spoon floor ellipse covered by the footprints of `positions` (N, 3)."""
    if len(positions) == 0:
        return 0.0
    xs = np.arange(-spoon.half_length, spoon.half_length + _GRID, _GRID)
    ys = np.arange(-spoon.half_width, spoon.half_width + _GRID, _GRID)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    cells = (gx / spoon.half_length) ** 2 + (gy / spoon.half_width) ** 2 <= 1.0
    px, py = gx[cells], gy[cells]
    local = in_spoon_frame(positions, spoon_pose)
    d2 = (px[:, None] - local[None, :, 0]) ** 2 + (py[:, None] - local[None, :, 1]) ** 2
    covered = (d2 <= radii[None, :] ** 2).any(axis=1)
    return float(covered.mean())


SPILL_STAGES = ("scoop", "lift", "carry", "pour", "after_pour")
SPILL_CAUSES = ("over_rim", "off_spoon", "poured_outside", "bounced_out", "posture_flip")
# A particle that left the spoon within this many actions after one the arm executed faster than
# the Panda's limit was thrown by it: a grain flung 20-30 cm falls for 0.2-0.25 s before it lands.
THROW_WINDOW = 3


def attribution_columns() -> dict[str, tuple[str, str]]:
    """Record column -> (stage, cause) of every stage x cause count: `spilled_<stage>_<cause>`."""
    return {f"spilled_{stage}_{cause}": (stage, cause) for stage in SPILL_STAGES for cause in SPILL_CAUSES}


def stage_columns(stage: str) -> list[str]:
    """The record columns of one stage's counts, one per cause: `spilled_<stage>_<cause>`."""
    return [f"spilled_{stage}_{cause}" for cause in SPILL_CAUSES]


def loose(counts: ParticleCounts) -> np.ndarray:
    """(N,) particles counted spilled now: outside the source bowl, the spoon and the target bowl,
    and not held by the spoon (`ParticleCounts.carried`)."""
    now = counts.outside_source & ~counts.in_spoon & ~counts.in_target
    return now if counts.carried is None else now & ~counts.carried


class SpillTracker:
    """Keeps the per-particle spilled flags, the spilled count after every action step, and for
    every spilled particle the stage and cause of its spill (docs/evaluation.md, "Where food is lost").

    Stage: the task stage the env was in (`stage`, set by the task runner: scoop, lift, carry,
    pour, after_pour) when the particle was first counted spilled. Cause, from where the particle
    was at the previous check (one per action) and how the arm moved:
    - over_rim: it lay in the source bowl (below the rim) and not in the spoon: it left over the rim.
    - bounced_out: it lay in the target bowl: it left it again (bounced or rolled out).
    - posture_flip: it came off the spoon within `THROW_WINDOW` actions after an action the arm
      executed faster than the Panda's velocity limit (`thrown`): the arm swung into another
      posture. With `SimConfig.joint_speed_cap` at 1 or below no action is executed that fast
      (a faster one is slowed), so the cause stays empty and such losses count as off_spoon.
    - poured_outside: it came off the spoon in the pour or after it and landed outside the target.
    - off_spoon: it came off the spoon (or off the heap the spoon carries) while the spoon moved.
    A grain the spoon still holds through contacts (`ParticleCounts.carried`, the overhang of a
    heap) is not spilled, however far outside the spoon's volume its centre lies: it is counted
    when it leaves the load, in the stage it leaves it.
    A particle that comes to rest in the target bowl is no longer counted (its flag is cleared), so
    one that bounces out later counts once more, as bounced_out.
    """

    def __init__(self, n_particles: int) -> None:
        self.spilled_flags = np.zeros(n_particles, dtype=bool)
        self.stage_index = np.full(n_particles, -1, dtype=np.int8)  # into SPILL_STAGES, -1 not spilled
        self.cause_index = np.full(n_particles, -1, dtype=np.int8)  # into SPILL_CAUSES
        self.spill_step = np.full(n_particles, -1, dtype=np.int32)  # the update (action step) that last counted it spilled
        self.history: list[int] = []
        self.first_spill_step = -1
        self.stage = SPILL_STAGES[0]
        self._was_in_bowl = np.zeros(n_particles, dtype=bool)
        self._was_in_target = np.zeros(n_particles, dtype=bool)
        self._since_throw = THROW_WINDOW  # actions since the last one over the Panda's limit

    def set_stage(self, stage: str) -> None:
        """The task stage from the next update on (one of SPILL_STAGES); ValueError otherwise."""
        if stage not in SPILL_STAGES:
            raise ValueError(f"unknown stage {stage!r}; one of {', '.join(SPILL_STAGES)}")
        self.stage = stage

    def observe(self, counts: ParticleCounts) -> None:
        """Remember where particles are (the reference for the next update's causes)."""
        self._was_in_bowl = counts.in_source & ~counts.in_spoon
        self._was_in_target = counts.in_target & ~counts.in_spoon

    def update(self, counts: ParticleCounts, thrown: bool = False) -> int:
        """Account for the state after one action; `thrown`: the arm executed that action faster than
        the Panda's limit allows (ScoopEnv.step). Returns the spilled count."""
        self._since_throw = 0 if thrown else self._since_throw + 1
        now = loose(counts)
        new = now & ~self.spilled_flags
        if new.any():
            stage = SPILL_STAGES.index(self.stage)
            from_spoon = ("posture_flip" if self._since_throw < THROW_WINDOW
                          else "poured_outside" if stage >= SPILL_STAGES.index("pour") else "off_spoon")
            cause = np.where(self._was_in_bowl[new], SPILL_CAUSES.index("over_rim"),
                             np.where(self._was_in_target[new], SPILL_CAUSES.index("bounced_out"), SPILL_CAUSES.index(from_spoon)))
            self.cause_index[new] = cause
            self.stage_index[new] = stage
            self.spill_step[new] = len(self.history)
        self.spilled_flags |= now
        self.spilled_flags &= ~counts.in_target  # food that reached the target bowl is delivered
        self.observe(counts)
        spilled = int(self.spilled_flags.sum())
        if spilled > 0 and self.first_spill_step < 0:
            self.first_spill_step = len(self.history)
        self.history.append(spilled)
        return spilled

    def current(self, counts: ParticleCounts) -> int:
        return int((self.spilled_flags & ~counts.in_target).sum())

    def spill_steps(self, counts: ParticleCounts) -> np.ndarray:
        """(K,) int32: for each particle spilled now (not in the target bowl), the action step (index
        into `history`) at which it was last counted spilled."""
        return self.spill_step[self.spilled_flags & ~counts.in_target].astype(np.int32)

    def attribution(self, counts: ParticleCounts) -> dict[str, int]:
        """Spilled particles now (not in the target bowl) by stage and cause, keyed as `attribution_columns`."""
        spilled = self.spilled_flags & ~counts.in_target
        out = {}
        for column, (stage, cause) in attribution_columns().items():
            mask = spilled & (self.stage_index == SPILL_STAGES.index(stage)) & (self.cause_index == SPILL_CAUSES.index(cause))
            out[column] = int(mask.sum())
        return out
