"""Collection jobs by kind: load a collect config (`kind: demos` or `kind: spillage`) and run it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from grits_lab.config import config_from_dict, load_yaml
from grits_lab.errors import ConfigError, InputError


def load_collect_config(path: str | Path) -> Any:
    """DemosConfig or SpillageConfig, chosen by the file's `kind:` key."""
    from grits_lab.collection.demos import DemosConfig
    from grits_lab.collection.spillage_trials import SpillageConfig

    data = load_yaml(path)
    kinds = {"demos": DemosConfig, "spillage": SpillageConfig}
    kind = data.get("kind")
    if kind not in kinds:
        raise ConfigError(f"{path}: `kind` must be one of 'demos', 'spillage'. Got {kind!r}.")
    try:
        return config_from_dict(kinds[kind], data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def run_collection(config: Any, progress: bool = True, carry: Any = None) -> dict[str, Any]:
    """Run a demos or spillage collection to `config.output_dir`, resuming what is already there.

    carry: the transfer-and-pour runner a spillage config with `exit.kind: carry` needs
    (grits_lab/evaluation/carry.py `carry_to_target`; `spillage_trials.Carry`), handed down by the
    caller because collection does not import evaluation.

    Everything that can be checked is checked before the dataset directory is touched: the
    episode plan (names of foods and levels), an existing dataset's config, the carry runner and
    the Ray cluster.
    """
    from grits_lab.collection.driver import existing_manifest
    from grits_lab.io import ensure_writable_dir, exclusive_directory
    from grits_lab.runners.executor_config import check_reachable, cluster_address

    existing_manifest(config.output_dir, config.kind, config.identity())
    specs, given_base = None, None
    if config.kind == "demos":
        from grits_lab.collection.demos import plan_demos

        specs = plan_demos(config)
    else:
        from grits_lab.collection.spillage_trials import require_carry

        require_carry(config, carry)
        if config.base_trajectory is not None:  # a file or dataset the user named: read (and refused) before the directory exists
            given_base = base_trajectory(config)
    check_reachable(cluster_address(config.executor))
    out = ensure_writable_dir(config.output_dir)
    with exclusive_directory(out, "collect"):  # one collector per dataset: two would write the same episodes
        return _collect_in(config, specs, given_base, progress, carry)


def _collect_in(config: Any, specs: list[Any] | None, given_base: np.ndarray | None, progress: bool, carry: Any) -> dict[str, Any]:
    from grits_lab.collection.driver import DatasetWriter, run_fixed_job
    from grits_lab.runners.executor_config import make_executor

    writer = DatasetWriter(config.output_dir, config.kind, config.identity())
    if specs is not None:
        with make_executor(config.executor) as executor:
            return run_fixed_job(executor, writer, specs, desc="demos", spilled_of=lambda m: m.get("spilled_any"), progress=progress)
    from grits_lab.collection.spillage_trials import BASE_TRAJECTORY_FILE, run_spillage_job, source_bowl_region

    base_path = writer.out_dir / BASE_TRAJECTORY_FILE
    if base_path.exists():
        base = np.load(base_path, allow_pickle=False)  # the one this dataset started with: resume stays identical
    else:
        base = given_base if given_base is not None else base_trajectory(config)
        from grits_lab.io import atomic_path

        with atomic_path(base_path) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, base)
    with make_executor(config.executor) as executor:
        return run_spillage_job(config, executor, writer, base, source_bowl_region(config), progress=progress, carry=carry)


def base_trajectory(config: Any) -> np.ndarray:
    """The spillage dataset's base trajectory: from a file, a demos dataset, or fresh expert plans."""
    from grits_lab.data.trajectories import as_pose9, mean_trajectory

    src = config.base_trajectory
    if src is None:
        from grits_lab.collection.spillage_trials import expert_mean_trajectory

        return expert_mean_trajectory(config)
    path = Path(src)
    if path.is_dir():
        from grits_lab.data.format import list_episode_files, read_episode

        actions = [read_episode(p, keys=["action"])[0]["action"] for p in list_episode_files(path)]
        if not actions:
            raise InputError(f"base_trajectory: no episodes in {path}")
        return mean_trajectory(actions)
    if path.suffix == ".npy" and path.is_file():
        try:
            return as_pose9(np.load(path, allow_pickle=False))
        except ValueError as exc:
            raise InputError(f"base_trajectory {path}: {exc}") from None
    raise InputError(f"base_trajectory must be a .npy file or a dataset directory; not found: {path}")
