"""A sweep tunes a lab's registered controller over rho and s like GRITS, when its class takes them,
and refuses, before any study exists, one that takes no guidance parameters."""

from __future__ import annotations

import functools
from pathlib import Path

import pandas as pd
import pytest
import yaml

from grits_lab.cli import main
from grits_lab.evaluation.custom_methods import CustomMethodConfig, controller_class
from tests.evaluation.test_custom_methods import EXAMPLE, tiny_config
from tests.tune.test_sweep_cli import one_error_line

GUIDED = {"controller": f"{EXAMPLE}:GuidedTorchPolicyController", "options": {"hidden": 16, "seed": 0}}
UNGUIDED = {"controller": f"{EXAMPLE}:TorchPolicyController", "options": {"hidden": 16, "seed": 0}}


def custom_sweep(sweep_file, tmp_path: Path, method: str, n_trials: int = 2) -> Path:
    """A sweep file whose trials evaluate `method`, registered with the two example controllers in
    a tiny serial evaluation config, on two validation episodes."""
    evaluation = tiny_config(tmp_path, methods=["torch_mlp_guided"],
                             custom_methods={"torch_mlp_guided": GUIDED, "torch_mlp": UNGUIDED})
    (tmp_path / "evaluate.yaml").write_text(yaml.safe_dump(evaluation, sort_keys=False))
    return sweep_file("custom", n_trials=n_trials, evaluator="grits",
                      rho={"low": 0.5, "high": 4.0, "log": False}, s={"low": 0, "high": 8, "step": 1},
                      enqueue=[{"rho": 2.0, "s": 4}], sampler={"name": "random", "seed": 5, "n_startup_trials": 0},
                      validation={"foods": ["chocolate_balls"], "levels": ["low"], "trials": 2, "seed": 11},
                      evaluation={"config": str(tmp_path / "evaluate.yaml"), "method": method, "checkpoints": []})


def test_a_sweep_tunes_a_registered_guided_controller_and_its_records_carry_each_trials_rho_and_s(
        sweep_file, tmp_path, capsys, monkeypatch):
    path = custom_sweep(sweep_file, tmp_path, "torch_mlp_guided")
    # The class the serial workers build (the example file is loaded once per process), watched
    # for the keyword arguments each episode's controller gets.
    cls = controller_class("torch_mlp_guided", CustomMethodConfig(**GUIDED))
    built: list[tuple[float, int]] = []
    init = cls.__init__

    @functools.wraps(init)
    def watched(self, *args, **kwargs):
        built.append((kwargs["rho"], kwargs["s"]))
        init(self, *args, **kwargs)

    monkeypatch.setattr(cls, "__init__", watched)
    assert main(["sweep", str(path), "--no-progress", "--no-plots"]) == 0
    assert "registered controller torch_mlp_guided" in capsys.readouterr().err
    folder = tmp_path / "results" / "custom"
    trials = pd.read_parquet(folder / "trials.parquet")
    assert list(trials["state"]) == ["COMPLETE", "COMPLETE"]
    assert (trials.loc[0, "rho"], trials.loc[0, "s"]) == (2.0, 4)  # the enqueued point first
    assert trials["rho"].nunique() == 2
    for trial in trials.itertuples():
        records = pd.read_parquet(folder / "records" / f"trial_{trial.number:05d}.parquet")
        assert len(records) == 2 and (records["method"] == "torch_mlp_guided").all() and records["error"].eq("").all()
        assert records["rho"].tolist() == [pytest.approx(trial.rho)] * 2 and records["s"].tolist() == [trial.s] * 2
    assert built == [(pytest.approx(r), s) for r, s in zip(trials["rho"], trials["s"]) for _ in range(2)]
    best = yaml.safe_load((folder / "best.yaml").read_text())
    assert set(best) == {"guidance"} and "GRITS" not in (folder / "best.yaml").read_text()


@pytest.mark.parametrize("method, lacks", [
    ("torch_mlp", f"{EXAMPLE}:TorchPolicyController has no keyword arguments `rho` and `s`"),
    ("dp", "of the built-in methods only grits, grits_raw, grits_pointnet2, grits_horizon sample with `guidance`"),
], ids=["registered", "built-in"])
def test_a_method_that_takes_no_guidance_parameters_is_refused_before_the_study_exists(
        sweep_file, tmp_path, capsys, method, lacks):
    path = custom_sweep(sweep_file, tmp_path, method)
    assert main(["sweep", str(path), "--no-progress"]) == 2
    assert one_error_line(capsys) == f"grits-lab: error: `evaluation.method`: {method} takes no guidance parameters: {lacks}"
    assert not (tmp_path / "results").exists()
