"""The evaluation episode record: one row per (method, food, level, trial), the unit every report reads.

Evaluation (`grits-lab evaluate`) and sweeps write these rows to Parquet; the report layer reads
them and never recomputes a metric. Boolean outcome columns may overlap (a trial can spill and
still fail to scoop), as in the paper.
"""

from __future__ import annotations

# The paper's ten unseen test foods in its order (SPEC "Foods"), as named in grits_lab/sim/foods.yaml:
# the evaluation's default foods and the order of every per-food table and figure.
UNSEEN_FOODS: tuple[str, ...] = (
    "sago", "red_bean", "mentos", "marshmallow", "fudge", "penne", "prune", "ramen_snack", "nuts", "milk_tea",
)

# name -> meaning. Every evaluation record has at least these columns.
RECORD_COLUMNS: dict[str, str] = {
    "run_id": "identifier of the evaluation or sweep run that produced the row",
    "protocol": "task and evaluation protocol the episode ran under, e.g. scoop-v4 (grits_lab/versions.py, docs/protocol.md)",
    "method": "method name, e.g. rule_based, bc, scone, dp, dp_post, grits, grits_raw, grits_pointnet2, grits_horizon",
    "food": "food name from the food library, e.g. sago",
    "split": "train or unseen",
    "level": "quantity level name, e.g. low or high",
    "trial": "trial index within (food, level), 0-based",
    "seed": "episode seed, derived from (root seed, food, level, trial); the same for every method",
    "task_success": "bool: scooped and transferred to the target bowl without spillage",
    "spillage": "bool: food spilled during scooping",
    "scoop_failure": "bool: nothing, or too little, lifted in the spoon",
    "scoop_success": "bool: lifted at least one large item or covered one third of the spoon",
    "spilled_before_scoop": "bool: spillage at any point before the scoop completed (paper Fig. 6)",
    "n_particles": "int: particles in the source bowl at the start",
    "spilled": "int: particles spilled during scooping",
    "scooped": "int: particles in the spoon when the scoop completed",
    "transferred": "int: particles that reached the target bowl",
    "rho": "float: guidance weight (NaN for methods without guidance)",
    "s": "int: guidance threshold on the training-step scale (-1 without guidance)",
    "error": "str: empty, or the error that ended the episode (such rows count as failures)",
    "wall_time_s": "float: wall-clock seconds for the episode",
}

OUTCOME_COLUMNS = ("task_success", "spillage", "scoop_failure")
# The record column naming the SIMD kernels its episode ran on (grits_lab/versions.py `cpu_kernels`);
# dataset episodes and checkpoints carry a key of the same name. Records from before it lack it.
CPU_KERNELS = "cpu_kernels"
# The record column naming the code its episode ran: the driver's `git_commit()` (grits_lab/versions.py)
# when the run that played it started, `<sha>` or `<sha> (with uncommitted changes)`. One run directory
# may hold episodes of several invocations at several commits. Records from before it lack it.
CODE_COMMIT = "code_commit"
# Where the lifted load (the particles `scooped` counts) was at the episode's end, each counted once:
# in the target bowl, still in the spoon, back in the source bowl, counted spilled, anywhere else;
# the five sum to `scooped` (grits_lab/evaluation/task_episode.py `load_account`). Records from
# scoop-v11 on.
LOAD_ACCOUNT = ("lifted_delivered", "lifted_in_spoon", "lifted_in_source", "lifted_spilled", "lifted_elsewhere")

# Records written before the `protocol` column existed: those that carry the stage x cause spill
# columns (`spilled_scoop_<cause>`, ...) were made by scoop-v4's code, which introduced them.
FIRST_RECORDED_PROTOCOL = "scoop-v4"
UNVERSIONED = "unversioned (before scoop-v4)"


def with_protocol(frame):
    """`frame`, the records of one file, with every row's `protocol` set (a copy; pandas DataFrame).

    A row without one predates the column: it gets FIRST_RECORDED_PROTOCOL when the file has the
    stage x cause spill columns that version introduced, UNVERSIONED otherwise (docs/protocol.md).
    """
    inferred = FIRST_RECORDED_PROTOCOL if any(str(c).startswith("spilled_scoop_") for c in frame.columns) else UNVERSIONED
    frame = frame.copy()
    if "protocol" not in frame.columns:
        frame["protocol"] = inferred
    else:
        recorded = frame["protocol"]
        frame["protocol"] = recorded.where(recorded.notna() & (recorded.astype(str).str.strip() != ""), inferred).astype(str)
    return frame


def error_text(errors):
    """The `error` column as text, "" where an episode raised nothing (a pandas Series of str).

    A file whose episodes all succeeded stores the column as all-null floats; filling those with a
    string is deprecated in pandas, so nulls are replaced on an object copy."""
    return errors.astype(object).where(errors.notna(), "").astype(str)


def has_error(errors):
    """Per episode, whether its `error` column holds any text other than whitespace (a boolean pandas
    Series). The one rule for what counts as a failed episode: evaluate's summary, the sweep
    objective and the report all ask it."""
    return error_text(errors).str.strip().str.len() > 0


# Per-plan guidance columns (`guidance.compare_unguided`): one list per episode, one entry per plan.
PLAN_COLUMNS = ("plan_p_spill_unguided", "plan_p_spill_guided", "plan_displacement_mm")


def plan_guidance_effect(frame) -> dict | None:
    """What guidance did over every compared plan of the records in `frame` (a pandas frame with
    PLAN_COLUMNS): {plans, p_spill_unguided, p_spill_guided (medians of the predictor's P(spill) of
    the unguided sample from the same noise and of the executed one), relative_change ((guided -
    unguided) / unguided of the medians; negative: lowered), p_spill_spread (standard deviation of
    the unguided P(spill)), displacement_mm (median distance between their executed spoon positions,
    mm per waypoint)}; None when the records hold no compared plan."""
    import numpy as np

    if frame is None or len(frame) == 0 or not set(PLAN_COLUMNS) <= set(frame.columns):
        return None
    flat: list[list] = [[], [], []]
    for values in zip(*(frame[c] for c in PLAN_COLUMNS)):
        if any(v is None or (isinstance(v, float) and np.isnan(v)) for v in values):
            continue
        for store, value in zip(flat, values):
            store.extend(np.asarray(value, dtype=float).reshape(-1).tolist())
    if not flat[0]:
        return None
    before, after = float(np.median(flat[0])), float(np.median(flat[1]))
    return {"plans": len(flat[0]), "p_spill_unguided": before, "p_spill_guided": after,
            "relative_change": (after - before) / before if before > 0 else float("nan"),
            "p_spill_spread": float(np.std(flat[0])), "displacement_mm": float(np.median(flat[2]))}
