"""Each pipeline stage: how its config is wired to the pipeline's layout, and how it runs.

`wire_<stage>` takes the stage YAML (as a mapping, user overrides already merged) and sets the
keys that connect stages: output locations, the datasets a trainer reads, the checkpoints an
evaluation loads. `run_<stage>` runs the stage from its wired YAML file through the same loader
and entry point the stage's own command uses, so a pipeline stage is exactly the job a user
would get from `grits-lab collect/train/evaluate/sweep/report` with that file.
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from grits_lab.config import merge_mappings
from grits_lab.errors import ConfigError, InputError
from grits_lab.pipeline.pipeline_config import STAGE_ORDER


@dataclass(frozen=True)
class Layout:
    """Where every stage of one pipeline run writes, under `root`."""

    root: Path

    @property
    def configs(self) -> Path:
        return self.root / "configs"

    def dataset(self, stage: str) -> Path:
        return self.root / "datasets" / stage

    @property
    def policy_dir(self) -> Path:
        return self.root / "policy"

    @property
    def bc_dir(self) -> Path:
        return self.root / "bc"

    @property
    def predictor_root(self) -> Path:
        return self.root / "predictor"

    def predictor_dir(self, stage: str) -> Path:
        return self.predictor_root / stage

    @property
    def evaluate_dir(self) -> Path:
        return self.root / "evaluate"

    @property
    def report_dir(self) -> Path:
        return self.root / "report"

    @property
    def sweep_dir(self) -> Path:
        """The sweep stage's study folder: journal.log (its Optuna storage), trials, best.yaml, records."""
        return self.evaluate_dir / "sweep"

    @property
    def sweep_evaluation_config(self) -> Path:
        """The evaluation config the sweep's trials start from: the evaluate stage's, before the sweep's best (rho, s)."""
        return self.configs / "sweep_evaluation.yaml"

    def stage_outputs(self, stage: str) -> list[Path]:
        """What a stage owns: removed before the stage re-runs under a changed config."""
        return {
            "demos": [self.dataset("demos")],
            "spillage": [self.dataset("spillage")],
            "spillage_heldout": [self.dataset("spillage_heldout")],
            "spillage_carry": [self.dataset("spillage_carry")],
            "policy": [self.policy_dir],
            "bc": [self.bc_dir],
            "predictor": [self.predictor_dir("predictor")],
            "predictor_raw": [self.predictor_dir("predictor_raw")],
            "predictor_pointnet2": [self.predictor_dir("predictor_pointnet2")],
            "predictor_horizon": [self.predictor_dir("predictor_horizon")],
            "evaluate": [self.evaluate_dir / "episodes.parquet", self.evaluate_dir / "records"],
            "sweep": [self.sweep_dir],
            "report": [self.report_dir],
        }[stage]


def policy_checkpoint(layout: Layout) -> Path:
    return layout.policy_dir / "checkpoints" / "last.pt"


def bc_checkpoint(layout: Layout) -> Path:
    return layout.bc_dir / "checkpoints" / "last.pt"


def predictor_checkpoint(layout: Layout, stage: str) -> Path:
    return layout.predictor_dir(stage) / "best.pt"


COLLECT_STAGES = ("demos", "spillage", "spillage_heldout", "spillage_carry")
PREDICTOR_STAGES = tuple(stage for stage in STAGE_ORDER if stage.startswith("predictor"))


def predictor_dataset(stage: str) -> str:
    """The collect stage a predictor stage trains on: the carry set (trials ending with the
    evaluation's transfer and pour, so that horizon labels reach delivery) for predictor_horizon,
    the lift-and-exit set for the others."""
    return "spillage_carry" if stage == "predictor_horizon" else "spillage"


def _executor(data: dict[str, Any], workers: int | None, address: str | None) -> dict[str, Any]:
    executor = dict(data.get("executor") or {})
    if workers is not None:
        executor["workers"] = workers
    if address is not None:
        executor["address"] = address
    return {**data, "executor": executor} if executor else data


def _writing_to(data: dict[str, Any], path: Path) -> dict[str, Any]:
    """`data` with `output_dir: path` (a retired spelling of that key fails when the stage's config loads)."""
    return {**data, "output_dir": str(path)}


def sweep_best(layout: Layout) -> dict[str, Any] | None:
    """The sweep stage's best point as an evaluation override (`guidance: {rho, s}` and the sweep's
    `evaluation.overrides`: grits_lab/tune/outputs.py), or None before the sweep has chosen one."""
    from grits_lab.config import load_yaml

    path = layout.sweep_dir / "best.yaml"
    return load_yaml(path) if path.is_file() else None


def wire(stage: str, data: dict[str, Any], layout: Layout, present: set[str],
         workers: int | None, address: str | None, tuned: bool = True) -> dict[str, Any]:
    """The stage's config mapping with the pipeline's links set. `present`: configured stages.

    With a sweep stage configured, the evaluate stage's guidance is the sweep's best point once the
    sweep has written it (`tuned`; with `tuned=False` the evaluation config the sweep starts from)."""
    if stage in COLLECT_STAGES:
        data = _writing_to(data, layout.dataset(stage))
        if stage != "demos" and "demos" in present:
            # the spillage trajectories are shifts of the mean demonstration (SPEC)
            data["base_trajectory"] = str(layout.dataset("demos"))
        return _executor(data, workers, address)
    if stage == "policy":
        return _writing_to({**data, "dataset": str(layout.dataset("demos"))}, layout.policy_dir)
    if stage == "bc":
        return _writing_to({**data, "dataset": str(layout.dataset("demos"))}, layout.bc_dir)
    if stage.startswith("predictor"):
        data = merge_mappings(data, {"data": {"dataset": str(layout.dataset(predictor_dataset(stage)))}})
        return _writing_to({**data, "name": stage}, layout.predictor_root)
    if stage == "evaluate":
        checkpoints: dict[str, str | None] = {
            "policy": str(policy_checkpoint(layout)) if "policy" in present else None,
            "bc": str(bc_checkpoint(layout)) if "bc" in present else None,
            "demos": str(layout.dataset("demos")) if "demos" in present else None,
        }
        for name in PREDICTOR_STAGES:
            checkpoints[name] = str(predictor_checkpoint(layout, name)) if name in present else None
        data = merge_mappings(data, {"checkpoints": checkpoints})
        if tuned and "sweep" in present and (best := sweep_best(layout)) is not None:
            data = merge_mappings(data, best)  # as `grits-lab evaluate --override best.yaml`
        data = _writing_to(data, layout.evaluate_dir)
        return _executor(data, workers, address)
    if stage == "sweep":
        own = dict(data.get("evaluation", {}))  # the sweep file's own keys (its `overrides`) stay, but the links are the pipeline's:
        if "checkpoints" in (own.get("overrides") or {}):  # the evaluation config it starts from holds this pipeline's checkpoints
            own["overrides"] = {k: v for k, v in own["overrides"].items() if k != "checkpoints"}
        evaluation = {
            **own,
            "config": str(layout.sweep_evaluation_config),
            "checkpoints": [str(policy_checkpoint(layout)), str(predictor_checkpoint(layout, "predictor"))],
            "method": "grits",
        }
        return {**_writing_to({**data, "study_name": "sweep"}, layout.evaluate_dir), "evaluation": evaluation}
    if stage == "report":
        return _writing_to({**data, "run_dir": str(layout.evaluate_dir)}, layout.report_dir)
    raise ValueError(f"unknown stage {stage}")


def _kind(stage: str) -> str:
    return stage.split("_")[0] if stage.startswith("predictor") else stage


def load_stage(stage: str, config_path: Path) -> Any:
    """Parse a wired stage file with its command's loader and check what needs no upstream output.

    Keys and values, and for demos and evaluate the food and level names; nothing is written.
    Raises ConfigError or InputError with the loader's one-line message.
    """
    config = _LOADERS[_kind(stage)](config_path)
    if stage == "spillage_carry" and not (config.kind == "spillage" and config.exit.carries()):
        raise ConfigError("the spillage_carry stage collects trials that end with the evaluation's carry: its config needs "
                          "`kind: spillage` and `exit: {kind: carry}` (experiments/spillage_carry_cpu.yaml)")
    if stage == "predictor_horizon" and config.data.label != "horizon":
        raise ConfigError(f"the predictor_horizon stage trains on the horizon label: its config needs `data.label: horizon`, "
                          f"not {config.data.label!r} (experiments/predictor_cpu_carry_horizon.yaml)")
    return config


def check(stage: str, texts: dict[str, str], source: str | None = None) -> None:
    """Check a stage's wired YAML (`texts[stage]`) before the pipeline runs anything.

    `texts` maps every configured stage to its wired YAML; the sweep stage's validation episodes
    and evaluation overrides are checked against the evaluate stage's. `source` is the stage's
    config file, named in the error with the stage. Raises ConfigError or InputError.
    """
    with tempfile.TemporaryDirectory() as tmp:
        text = texts[stage]
        if stage == "sweep" and "evaluate" in texts:  # its validation episodes read the evaluate stage's config
            evaluate_path = Path(tmp) / "evaluate.yaml"
            evaluate_path.write_text(texts["evaluate"])
            data = yaml.safe_load(text)
            data["evaluation"] = {**data.get("evaluation", {}), "config": str(evaluate_path)}
            text = yaml.safe_dump(data, sort_keys=False)
        path = Path(tmp) / f"{stage}.yaml"
        path.write_text(text)
        try:
            load_stage(stage, path)
        except (ConfigError, InputError) as exc:
            where = f"stage `{stage}`" + (f" ({source} with its overrides)" if source else "")
            message = str(exc).replace(f"{tmp}/evaluate.yaml: ", "the evaluate stage's config with `evaluation.overrides`: ")
            raise type(exc)(f"{where}: {message.replace(f'{tmp}/', '').replace(f'{stage}.yaml: ', '')}") from None


def run(stage: str, config_path: Path, layout: Layout, progress: bool) -> dict[str, Any]:
    """Run one wired stage; returns a JSON-serializable summary."""
    return _RUNNERS[_kind(stage)](stage, load_stage(stage, config_path), layout, progress)


def _load_collect(path: Path) -> Any:
    from grits_lab.collection.demos import plan_demos
    from grits_lab.collection.jobs import load_collect_config

    config = load_collect_config(path)
    if config.kind == "demos":
        plan_demos(config)  # food and level names
    return config


def _load_policy(path: Path) -> Any:
    from grits_lab.policies.diffusion.training_diffusion import load_train_config

    return load_train_config(path)


def _load_bc(path: Path) -> Any:
    from grits_lab.policies.bc.training_bc import load_bc_config

    return load_bc_config(path)


def _load_predictor(path: Path) -> Any:
    from grits_lab.config import load_config
    from grits_lab.spillage.predictor_config import PredictorConfig

    return load_config(path, PredictorConfig)


def _load_evaluate(path: Path) -> Any:
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.evaluation.evaluation_run import episode_keys

    config = load_evaluation_config(path)
    episode_keys(config)  # food and level names
    return config


def _load_sweep(path: Path) -> Any:
    from grits_lab.tune.study_config import load_study_config

    return load_study_config(path)  # its validation episodes too, named against its evaluation config


def _load_report(path: Path) -> Any:
    from grits_lab.config import load_yaml

    return load_yaml(path)


def _run_collect(stage: str, config: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.collection.jobs import run_collection

    carry = None
    if config.kind == "spillage" and config.exit.carries():  # the evaluation's transfer and pour end each trial
        from grits_lab.evaluation.carry import carry_to_target

        carry = carry_to_target
    return run_collection(config, progress=progress, carry=carry)


def _run_policy(stage: str, config: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.evaluation.rollouts import ScoopRollouts
    from grits_lab.policies.diffusion.training_diffusion import train_policy

    return train_policy(config, progress=progress, rollouts=ScoopRollouts)


def _run_bc(stage: str, config: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.policies.bc.training_bc import train_bc

    return train_bc(config, progress=progress)


def _run_predictor(stage: str, config: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.io import write_json_atomic
    from grits_lab.report.predictor_quality import HELDOUT_FILE
    from grits_lab.spillage.predictor_checkpoint import load_predictor
    from grits_lab.spillage.predictor_training import evaluate_predictor, train_predictor

    summary = train_predictor(config, progress=progress)
    heldout = layout.dataset("spillage_heldout")
    if predictor_dataset(stage) == "spillage" and ((heldout / "index.parquet").exists() or (heldout / "episodes").is_dir()):
        predictor = load_predictor(predictor_checkpoint(layout, stage))
        summary = {**summary, "heldout": evaluate_predictor(predictor, heldout)}
        write_json_atomic(layout.predictor_dir(stage) / HELDOUT_FILE, summary["heldout"])  # the report's calibration line
    if summary.get("degenerate"):
        print(f"warning: predictor `{stage}` is degenerate: {summary['degenerate']}; guidance has nothing to act on",
              file=sys.stderr, flush=True)
    return summary


def _run_evaluate(stage: str, config: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.evaluation.evaluation_run import evaluate, summary_table

    records = evaluate(config, progress=progress)
    print(summary_table(records))
    return {"episodes": len(records)}


def _run_sweep(stage: str, config: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.tune.job import run_sweep

    return run_sweep(config, progress=progress)


def _run_report(stage: str, data: Any, layout: Layout, progress: bool) -> dict[str, Any]:
    from grits_lab.report.build import build_report

    training = [d for d in (layout.policy_dir, layout.bc_dir, layout.predictor_root) if d.is_dir()]
    result = build_report(data["run_dir"], data["output_dir"], training=training)
    return {"output_dir": str(result.out_dir), "files": len(result.files), "missing": list(result.missing)}


_LOADERS: dict[str, Callable[[Path], Any]] = {
    **{stage: _load_collect for stage in COLLECT_STAGES},
    "policy": _load_policy,
    "bc": _load_bc,
    "predictor": _load_predictor,
    "evaluate": _load_evaluate,
    "sweep": _load_sweep,
    "report": _load_report,
}

_RUNNERS: dict[str, Callable[[str, Any, Layout, bool], dict[str, Any]]] = {
    **{stage: _run_collect for stage in COLLECT_STAGES},
    "policy": _run_policy,
    "bc": _run_bc,
    "predictor": _run_predictor,
    "evaluate": _run_evaluate,
    "sweep": _run_sweep,
    "report": _run_report,
}
