"""Spillage dataset: shifted mean-expert trajectories over random primitive foods, labelled by simulation, balanced.

A candidate trial (shape, k) draws its particle parameters and its trajectory shift from its own
seed, runs the shifted base scoop and then takes the load away from the bowl (`exit.kind`): by
default the evaluation's own transfer and pour to the target bowl ("carry", run by the callable
the job is handed), or the earlier lift-and-exit at a drawn speed ("exit"). It records the
spilled count after every step. The scoop (with the exit, the whole trajectory) is cut into
chunks of `n_action_steps` waypoints (the policy's); each chunk stores the composite and raw
clouds observed at its start and two labels (grits_lab/data/chunk_labels.py): whether the
spilled count rose during the chunk (the paper's), and whether food spilled from its first
action until the load was delivered (horizon). The trial's label of each kind is 1 if any chunk's
is. Candidates are accepted in index order per shape until every (shape, label) bucket of the
label `balance_on` names is full (`grits_lab.collection.balance`); the acceptance rate is reported.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Literal

import numpy as np

from grits_lab.config import require
from grits_lab.data.chunk_labels import TRIAL_LABELS, Label, chunk_labels, horizon_labels
from grits_lab.perception.composite import CloudConfig
from grits_lab.records import CPU_KERNELS
from grits_lab.runners.executor_config import ExecutorConfig
from grits_lab.runners.spec import EpisodeSpec
from grits_lab.seeding import derive_seed, make_rng
from grits_lab.sim.sim_config import SimConfig
from grits_lab.sim.foods import SHAPES, ParticleRanges, primitive_food
from grits_lab.task.transfer_settings import TransferSettings
from grits_lab.versions import cpu_kernels

# The carry after a trial's scoop: carry(env, cloud_builder, seed, settings) runs the evaluation's
# transfer and pour on the live env and returns its measurements (grits_lab/evaluation/carry.py
# `carry_to_target`). Handed down by the job's caller: collection does not import evaluation.
Carry = Callable[[Any, Any, int, TransferSettings], dict[str, Any]]


@dataclass
class ShiftConfig:
    # Uniform shift of the mean trajectory's positions (paper: +-7 cm X, +-5 cm Y and Z).
    x: float = 0.07
    y: float = 0.05
    z: float = 0.05
    # The spoon's centre stays this far inside the bowl's inner wall (half the spoon's width).
    clearance: float = 0.02
    ramp_steps: int = 5

    def __post_init__(self) -> None:
        for key in ("x", "y", "z", "clearance"):
            require(getattr(self, key) >= 0, f"shift.{key}", getattr(self, key), "non-negative")


@dataclass
class ExitConfig:
    # What takes the load away after the scoop; food that falls outside the bowl on the way is
    # spillage, and the horizon label sees it.
    enabled: bool = True  # false: the trial ends with its scoop
    # "carry": the evaluation's own transfer and pour to the target bowl (`transfer`: its path,
    # speed and settling; docs/evaluation.md), so a chunk's horizon label sees what its scoop leads
    # to on the way `grits-lab evaluate` takes. "exit": the earlier lift-and-exit out of the bowl
    # at a drawn speed (the keys below, which only it reads), as datasets made before the carry.
    kind: Literal["carry", "exit"] = "carry"
    transfer: TransferSettings = field(default_factory=TransferSettings)
    distance: float = 0.14  # spoon centre this far from the bowl axis at the end (outer rim: 8.6 cm)
    rise: float = 0.02  # metres gained on the way out
    # Average exit speed (m/s, eased in and out), drawn per trial: a brisk exit sheds a loaded
    # spoon's top layer, a slow one keeps it, so the speed is part of what decides the label.
    speed: tuple[float, float] = (0.25, 0.8)
    # Roll of the spoon about its direction of travel once it is outside the bowl (degrees,
    # magnitude drawn per trial, sign random), over `tilt_steps` actions: how far the spoon tips
    # decides whether its load slides off, and only the trajectory carries it, so the predictor
    # has to read the trajectory, not just the cloud at the chunk's start. (0, 0) stays level.
    # Off by default: no policy rolls a loaded spoon; spills come from the shifted scoop itself.
    tilt_deg: tuple[float, float] = (0.0, 0.0)
    tilt_steps: int = 6
    # Direction of the exit in the table plane, degrees from the world +x axis (away from the
    # robot). Not towards the target workspace: with the scoop's orientation the arm cannot reach
    # that way (every exit waypoint failed IK, so the spoon froze over the bowl); 0 degrees is
    # reachable for every shift and tilt of the default ranges.
    direction_deg: float = 0.0
    hold_steps: int = 5  # actions holding still at the end so falling food lands

    def __post_init__(self) -> None:
        require(self.distance > 0, "exit.distance", self.distance, "positive")
        require(0 < self.speed[0] <= self.speed[1], "exit.speed", list(self.speed), "a range [low, high] with 0 < low <= high")
        require(0 <= self.tilt_deg[0] <= self.tilt_deg[1] <= 90, "exit.tilt_deg", list(self.tilt_deg), "a range [low, high] with 0 <= low <= high <= 90")
        require(self.tilt_steps >= 1, "exit.tilt_steps", self.tilt_steps, "at least 1")
        require(self.hold_steps >= 0, "exit.hold_steps", self.hold_steps, "non-negative")
        if self.kind == "carry":
            require(self.transfer.enabled, "exit.transfer.enabled", self.transfer.enabled,
                    "true with `exit.kind` carry (`exit.enabled: false` ends a trial with its scoop)")
            require(tuple(self.tilt_deg) == (0.0, 0.0), "exit.tilt_deg", list(self.tilt_deg),
                    "[0, 0] with `exit.kind` carry (the roll belongs to the lift-and-exit)")

    def carries(self) -> bool:
        """Whether trials end with the evaluation's transfer and pour."""
        return self.enabled and self.kind == "carry"

    def direction_xy(self) -> np.ndarray:
        """Unit vector of the exit in the table plane."""
        angle = np.deg2rad(self.direction_deg)
        return np.array([np.cos(angle), np.sin(angle)])


@dataclass
class SpillageConfig:
    retired_keys: ClassVar[dict[str, str]] = {"output": "output_dir", "trials": "episodes"}

    kind: Literal["spillage"] = "spillage"
    output_dir: str = "results/datasets/spillage"
    seed: int = 0
    # Episodes (spillage trials) the dataset keeps: an equal share per shape, split by
    # spill_fraction into spill and no-spill; candidates are run until every share is full.
    episodes: int = 4000
    spill_fraction: float = 0.5
    shapes: list[str] = field(default_factory=lambda: list(SHAPES))
    n_action_steps: int = 12  # waypoints per chunk: the policy's n_action_steps (authors' code: 12)
    # The trial label whose (shape, label) buckets are filled: "chunk" (some chunk's own actions
    # spilled, the paper's) or "horizon" (food spilled before the load was delivered). Both are
    # stored either way; balance on the one the predictor will train on (`data.label`).
    balance_on: Label = "chunk"
    # Base trajectory: a (T, 9)/(T, 7) .npy file or a demonstrations dataset directory (the mean
    # of its `action`s); null = the scripted expert: its nominal (unrandomized) scoop when
    # base_expert_plans is 0, else the time-normalized mean of that many randomized expert plans.
    base_trajectory: str | None = None
    base_expert_plans: int = 0
    # Candidates tried per shape before giving up on unfilled buckets, as a multiple of the
    # shape's share of `episodes`.
    max_candidates_factor: float = 20.0
    raw_cloud: bool = True
    particles: ParticleRanges = field(default_factory=ParticleRanges)
    shift: ShiftConfig = field(default_factory=ShiftConfig)
    exit: ExitConfig = field(default_factory=ExitConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    cloud: CloudConfig = field(default_factory=CloudConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)

    def __post_init__(self) -> None:
        require(self.episodes >= 1, "episodes", self.episodes, "at least 1")
        require(0 <= self.spill_fraction <= 1, "spill_fraction", self.spill_fraction, "in [0, 1]")
        require(len(self.shapes) >= 1 and set(self.shapes) <= set(SHAPES), "shapes", self.shapes, f"a non-empty subset of {list(SHAPES)}")
        require(self.episodes % len(self.shapes) == 0, "episodes", self.episodes, f"a multiple of the number of shapes ({len(self.shapes)})")
        require(self.n_action_steps >= 1, "n_action_steps", self.n_action_steps, "at least 1")
        require(self.base_expert_plans >= 0, "base_expert_plans", self.base_expert_plans, "non-negative")
        require(self.max_candidates_factor >= 1, "max_candidates_factor", self.max_candidates_factor, "at least 1")
        if self.exit.carries():
            self.exit.transfer.require_time_step_fits(self.sim, "exit.transfer.time_step")

    def identity(self) -> dict[str, Any]:
        """What determines the data (the executor and the output path do not)."""
        from grits_lab.collection.driver import collection_identity

        identity = collection_identity(self)
        # The fingerprint's recipe is fixed, not a reader of old names: it hashes the dataset's size
        # as `trials`, as every stored dataset's fingerprint (this protocol's included) was taken;
        # renaming it here would refuse them all as "made with a different config".
        identity["trials"] = identity.pop("episodes")
        # Keys added with the carry and the horizon label, left out at the values that make the data
        # of before them, so datasets made then keep their fingerprint.
        if self.balance_on == "chunk":
            del identity["balance_on"]
        if self.exit.kind == "exit" or not self.exit.enabled:
            del identity["exit"]["kind"], identity["exit"]["transfer"]
        return identity

    def targets(self) -> dict[str, tuple[int, int]]:
        """(no-spill, spill) episodes per shape: 4000 at 0.5 -> 500 / 500 for each of 4 shapes."""
        per_shape = self.episodes // len(self.shapes)
        spill = int(round(per_shape * self.spill_fraction))
        return {shape: (per_shape - spill, spill) for shape in self.shapes}


@dataclass
class SpillageTrialParams:
    """What a worker needs for one candidate trial besides the spec's seed and trajectory."""

    sim: SimConfig
    cloud: CloudConfig
    particles: ParticleRanges
    shape: str
    n_action_steps: int
    raw_cloud: bool
    shift: list[float]
    shift_scale: float
    exit_kind: str = "none"  # what followed the scoop: "carry", "exit" or "none"
    exit_speed: float = 0.0
    exit_tilt_deg: float = 0.0
    # With `exit.kind` carry: the transfer and pour run after the scoop, and their settings.
    carry: Carry | None = None
    transfer: TransferSettings | None = None


CANDIDATE_LOG = "candidates.jsonl"
BASE_TRAJECTORY_FILE = "base_trajectory.npy"


def candidate_id(shape: str, index: int) -> str:
    return f"{shape}-{index:06d}"


def trial_label(meta: dict[str, Any], label: Label) -> int:
    """A trial's label of the given kind from its meta (datasets made before horizon labels have only "label")."""
    return int(meta[TRIAL_LABELS[label]])


class CandidateLog:
    """Append-only record of every decided candidate (JSON lines), so a resumed job does not re-run them.

    A torn last line (the job was killed while writing it) is ignored; that candidate is decided
    again from its episode file or by re-running it.
    """

    def __init__(self, path: Path):
        self.path = path

    def read(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        if not self.path.exists():
            return out
        for line in self.path.read_text().splitlines():
            try:
                rec = json.loads(line)
                out[rec["id"]] = rec
            except (json.JSONDecodeError, KeyError, TypeError):
                continue
        return out

    def append(self, record: dict[str, Any]) -> None:
        import os

        with open(self.path, "a") as fh:
            fh.write(json.dumps(record, sort_keys=True) + "\n")
            fh.flush()
            os.fsync(fh.fileno())


def make_trial_spec(config: SpillageConfig, base: np.ndarray, bowl: dict[str, Any], shape: str, index: int,
                    carry: Carry | None = None) -> EpisodeSpec:
    """The spec of candidate (shape, index): its seed, its shifted trajectory and its parameters.

    carry: the transfer-and-pour runner, required when the config's exit is the carry.
    """
    from grits_lab.data.trajectories import append_exit, shift_trajectory

    seed = derive_seed(config.seed, "spillage", shape, index)
    exit_speed = exit_tilt = 0.0
    if config.exit.carries():
        require_carry(config, carry)
    elif config.exit.enabled:
        e = config.exit
        exit_speed = float(make_rng(derive_seed(seed, "exit")).uniform(*e.speed))
        tilt_rng = make_rng(derive_seed(seed, "exit-tilt"))
        exit_tilt = float(tilt_rng.uniform(*e.tilt_deg) * tilt_rng.choice([-1.0, 1.0]))
        base = append_exit(
            base, bowl["center"], e.direction_xy(), e.distance, e.rise, exit_speed, e.hold_steps, config.sim.control_hz,
            tilt=np.deg2rad(exit_tilt), tilt_steps=e.tilt_steps,
        )
    rng = make_rng(derive_seed(seed, "shift"))
    s = config.shift
    shift = rng.uniform(-1.0, 1.0, 3) * np.array([s.x, s.y, s.z])
    traj, scale = shift_trajectory(
        base, shift, bowl["center"], bowl["inner_radius_at"], bowl["rim_height"], bowl["floor_height"],
        clearance=s.clearance, ramp_steps=s.ramp_steps,
    )
    params = SpillageTrialParams(
        sim=config.sim, cloud=config.cloud, particles=config.particles, shape=shape, n_action_steps=config.n_action_steps,
        raw_cloud=config.raw_cloud, shift=[float(v) for v in shift], shift_scale=float(scale), exit_speed=exit_speed,
        exit_tilt_deg=exit_tilt, exit_kind=config.exit.kind if config.exit.enabled else "none",
        carry=carry if config.exit.carries() else None,
        transfer=config.exit.transfer if config.exit.carries() else None,
    )
    return EpisodeSpec(
        episode_id=candidate_id(shape, index), work=spillage_trial, seed=seed, trajectory=traj.astype(np.float32),
        params={"trial": params},
    )


def require_carry(config: SpillageConfig, carry: Carry | None) -> None:
    """ConfigError unless the carry runner is given when the config's trials end with the carry."""
    from grits_lab.errors import ConfigError

    if config.exit.carries() and carry is None:
        raise ConfigError("`exit.kind` is carry, but no carry runner was handed to the collection (`carry=`: "
                          "grits_lab.evaluation.carry_to_target, which `grits-lab collect` passes); "
                          "or set `exit.kind: exit`")


def run_spillage_job(config: SpillageConfig, executor: Any, writer: Any, base: np.ndarray, bowl: dict[str, Any], progress: bool = True,
                     carry: Carry | None = None) -> dict[str, Any]:
    """Generate candidates until every (shape, `balance_on` label) bucket is full; write accepted trials."""
    from grits_lab.collection.balance import BalancedAcceptor
    from grits_lab.collection.driver import Progress, failure_details, refuse_empty

    targets = config.targets()
    per_shape = config.episodes // len(config.shapes)
    acceptor = BalancedAcceptor(targets, max_candidates=int(np.ceil(per_shape * config.max_candidates_factor)))
    log = CandidateLog(writer.out_dir / CANDIDATE_LOG)
    logged = log.read()
    on_disk = writer.finished()
    stats = {"tried": 0, "spilled": 0, "failed": 0}
    bar = Progress(total=config.episodes, initial=0, desc="spillage", enabled=progress)

    def decide(decisions: list, from_log: bool) -> None:
        for d in decisions:
            cid = candidate_id(d.shape, d.index)
            stats["tried"] += 1
            stats["failed"] += int(d.label is None)
            stats["spilled"] += int(d.label == 1)
            if d.accepted and d.payload is not None:
                writer.write(cid, d.payload)
            elif not d.accepted and cid in on_disk:
                (writer.out_dir / "episodes" / f"{cid}.npz").unlink(missing_ok=True)
            if not from_log:
                log.append({"id": cid, "shape": d.shape, "index": d.index, "label": d.label, "accepted": d.accepted})
            if d.accepted:
                bar.spilled, bar.labelled = stats["spilled"], stats["tried"] - stats["failed"]
                bar.update(accept=f"{sum(sum(c.values()) for c in acceptor.counts().values()) / stats['tried']:.2f}")

    # Resume: replay decided candidates in index order (from the log, else from an episode file
    # written just before an interruption), so the acceptor ends where the last run stopped.
    for shape in config.shapes:
        k = 0
        while True:
            cid = candidate_id(shape, k)
            if cid in logged:
                acceptor.skip_to(shape, k + 1)
                decide(acceptor.add(shape, k, logged[cid]["label"]), from_log=True)
            elif cid in on_disk:
                acceptor.skip_to(shape, k + 1)
                decide(acceptor.add(shape, k, trial_label(on_disk[cid], config.balance_on)), from_log=False)
            else:
                break
            k += 1

    # Accepted trials whose files are gone (writer.finished() removes damaged files) are re-run
    # from their seeds; the simulation is deterministic, so they come back identical.
    start = time.perf_counter()  # regenerating lost trials is work of this run too
    missing = [(e["shape"], int(e["index"])) for cid, e in logged.items() if e.get("accepted") and cid not in on_disk]
    while missing or executor.pending():
        while missing and executor.capacity() > 0:
            executor.submit(make_trial_spec(config, base, bowl, *missing.pop(0), carry=carry))
        for result in executor.poll():
            if result.ok:
                writer.write(result.episode_id, result.payload)
            else:
                writer.write_failure(result.episode_id, failure_details(result))

    in_flight: dict[str, str] = {}
    failed_now, first_error = 0, ""  # this run's own trials, not the resumed log's
    try:
        while not acceptor.done():
            while executor.capacity() > 0:
                by_shape: dict[str, int] = {}
                for sh in in_flight.values():
                    by_shape[sh] = by_shape.get(sh, 0) + 1
                nxt = acceptor.next_candidate(by_shape)
                if nxt is None:
                    break
                spec = make_trial_spec(config, base, bowl, *nxt, carry=carry)
                executor.submit(spec)
                in_flight[spec.episode_id] = nxt[0]
            if executor.pending() == 0:
                break
            for result in executor.poll():
                shape = in_flight.pop(result.episode_id)
                index = int(result.episode_id.rsplit("-", 1)[1])
                if result.ok:
                    label = trial_label(result.payload["meta"], config.balance_on)
                    payload = result.payload
                else:
                    label, payload = None, None
                    writer.write_failure(result.episode_id, failure_details(result))
                    failed_now += 1
                    first_error = first_error or result.error
                decide(acceptor.add(shape, index, label, payload), from_log=False)
    finally:
        bar.close()
    counts = acceptor.counts()
    accepted = sum(sum(c.values()) for c in counts.values())
    labelled = stats["tried"] - stats["failed"]
    summary = {
        "episodes": accepted,
        "requested": config.episodes,
        "balanced_on": config.balance_on,
        "buckets": {f"{shape}/{label}": n for shape, c in counts.items() for label, n in c.items()},
        "targets": {f"{shape}/{label}": t[label] for shape, t in targets.items() for label in (0, 1)},
        "candidates_tried": stats["tried"],
        "candidates_failed": stats["failed"],
        "acceptance_rate": round(accepted / stats["tried"], 4) if stats["tried"] else None,
        "spill_rate_of_candidates": round(stats["spilled"] / labelled, 4) if labelled else None,
        "wall_time_s_this_time": round(time.perf_counter() - start, 2),
    }
    on_disk_now = len(list(writer.out_dir.glob("episodes/*.npz")))  # a trial that failed to regenerate is missing
    writer.finalize(summary, complete=all(acceptor.full(s) for s in config.shapes) and on_disk_now == accepted)
    refuse_empty("spillage", writer, accepted, failed_now, first_error)
    return summary


def source_bowl_region(config: SpillageConfig) -> dict[str, Any]:
    """Where the source bowl is and how wide it is at each height (for keeping shifts feasible)."""
    from grits_lab.sim.shapes import BowlGeometry

    sim = config.sim
    geometry = BowlGeometry()
    return {
        "center": np.array([sim.source_bowl_xy[0], sim.source_bowl_xy[1], 0.0]),
        "inner_radius_at": geometry.inner_radius_at,
        "rim_height": geometry.depth,
        "floor_height": geometry.floor_thickness,
    }


def expert_mean_trajectory(config: SpillageConfig) -> np.ndarray:
    """The scripted expert's nominal scoop, or the mean of `base_expert_plans` randomized ones (T, 9)."""
    from grits_lab.data.trajectories import mean_trajectory
    from grits_lab.sim.env import scene_geometry
    from grits_lab.sim.expert import expert_trajectory, nominal_expert_trajectory

    sim = config.sim
    scene = scene_geometry(sim, np.asarray(sim.target_workspace_center))
    if config.base_expert_plans == 0:
        return nominal_expert_trajectory(scene, sim.control_hz).astype(np.float64)
    plans = [
        expert_trajectory(scene, make_rng(derive_seed(config.seed, "base-plan", i)), sim.control_hz)
        for i in range(config.base_expert_plans)
    ]
    return mean_trajectory(plans)


def spillage_trial(spec: EpisodeSpec, context: Any) -> dict[str, Any]:
    """Run one candidate: random primitive food, the spec's trajectory (clouds at every chunk start), then the carry."""
    from grits_lab.config import config_fingerprint
    from grits_lab.perception.env_clouds import builder_for_env, scene_clouds
    from grits_lab.sim.env import worker_env

    p: SpillageTrialParams = spec.params["trial"]
    env = worker_env(context, p.sim)
    builder = context.cached(("cloud-builder", config_fingerprint(p.cloud)), lambda: builder_for_env(p.cloud, env))
    food, count = primitive_food(p.shape, make_rng(derive_seed(spec.seed, "food")), p.particles)
    obs, info = env.reset(seed=spec.seed, options={"food_spec": food, "n_particles": count})
    spilled_before = int(info["spilled"])
    trajectory = np.asarray(spec.trajectory, dtype=np.float32)
    spilled, clouds, clouds_raw, visible = [], [], [], []
    for t, action in enumerate(trajectory):
        if t % p.n_action_steps == 0:
            c = scene_clouds(builder, env, seed=derive_seed(spec.seed, "cloud", t), raw=p.raw_cloud)
            clouds.append(c["cloud"].astype(np.float16))
            if p.raw_cloud:
                clouds_raw.append(c["cloud_raw"].astype(np.float16))
                visible.append(c["raw_points"]["food"])
        obs, _, terminated, truncated, info = env.step(action)
        spilled.append(int(info["spilled"]))
        if terminated or truncated:
            break
    trajectory = trajectory[: len(spilled)]
    scooped = int(env.metrics()["scooped"])  # the load the carry takes away
    carried: dict[str, Any] = {}
    if p.carry is not None and scooped > 0:  # as in the evaluation: an empty spoon is not carried
        assert p.transfer is not None
        carried = p.carry(env, builder, spec.seed, p.transfer)
    # The count after every step from the first action until the load was delivered: the scoop's
    # steps, then the carry's (the env's tracker holds one entry per step).
    until_delivery = np.asarray(env.tracker.history, dtype=np.int32)
    chunk_start, chunk_spilled = chunk_labels(until_delivery, p.n_action_steps, spilled_before, n_steps=len(spilled))
    spill_steps = env.spill_steps()  # where each particle ended, once the load was delivered
    chunk_spilled_horizon = horizon_labels(spill_steps, chunk_start)
    metrics = env.metrics()
    component = env.particle_parameters()[0] if count else {}
    arrays = {
        "trajectory": trajectory,
        "chunk_start": chunk_start.astype(np.int32),
        "chunk_cloud": np.stack(clouds)[: len(chunk_start)],
        "chunk_spilled": chunk_spilled.astype(bool),
        "chunk_spilled_horizon": chunk_spilled_horizon.astype(bool),
        "spilled_over_time": np.asarray(spilled, dtype=np.int32),
        "spilled_until_delivery": until_delivery,
        "spill_steps": spill_steps,
    }
    if p.raw_cloud:
        arrays["chunk_cloud_raw"] = np.stack(clouds_raw)[: len(chunk_start)]
    meta = {
        "shape": p.shape,
        "seed": spec.seed,
        "label": int(chunk_spilled.any()),
        "label_horizon": int(chunk_spilled_horizon.any()),
        "n_chunks": int(len(chunk_start)),
        "n_chunks_spilled": int(chunk_spilled.sum()),
        "n_chunks_spilled_horizon": int(chunk_spilled_horizon.sum()),
        "spilled_at_start": spilled_before,
        "n_particles": int(metrics["n_particles"]),
        "spilled": int(metrics["spilled"]),
        "scooped": scooped,
        "scoop_success": bool(metrics["scoop_success"]),
        "ik_failures": int(metrics["ik_failures"]),
        "n_action_steps": p.n_action_steps,
        "steps": int(len(spilled)),
        "shift_x": p.shift[0],
        "shift_y": p.shift[1],
        "shift_z": p.shift[2],
        "shift_scale": p.shift_scale,
        "exit_kind": p.exit_kind,
        "exit_speed": p.exit_speed,
        "exit_tilt_deg": p.exit_tilt_deg,
        "radius": float(component.get("radius", 0.0)),
        "half_length": float(component.get("half_length", 0.0)),
        "mass": float(component.get("mass_mean", 0.0)),
        "friction": float(component.get("lateral_friction_mean", 0.0)),
        "min_visible_food_points": int(min(visible)) if visible else -1,
        CPU_KERNELS: cpu_kernels(),  # grits_lab/versions.py: what the worker computed with
        **metrics["spill_attribution"],
    }
    if p.carry is not None:
        meta["carry_steps"] = int(len(until_delivery) - len(spilled))
    if carried:
        meta.update({
            "transferred": int(metrics["transferred"]),
            "carry_plan": str(carried["plan"]),
            "carry_reachable": carried["reachable"],
            "carry_ik_failures": int(carried["ik_failures"]),
            "carry_peak_speed_mps": float(carried["carry_peak_speed_mps"]),
            # the spilled count when each stage ended (scoop, lift, carry, pour, after_pour)
            **{f"spilled_after_{stage}": int(n) for stage, n in carried["spilled_by_stage"].items()},
        })
    return {"arrays": arrays, "meta": meta}
