"""A lab's own controller, registered in the evaluation config or by an entry point, evaluated
through `grits-lab evaluate` and shown in the report, without editing the package."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import yaml

from grits_lab.cli import main
from grits_lab.config import config_from_dict
from grits_lab.errors import ConfigError, GritsError
from grits_lab.evaluation import custom_methods
from grits_lab.evaluation.evaluation_config import EvaluationConfig
from grits_lab.report import build_report

EXAMPLE = Path(__file__).parents[2] / "examples" / "torch_controller.py"
CUSTOM = {"torch_mlp": {"controller": f"{EXAMPLE}:TorchPolicyController", "options": {"hidden": 16, "seed": 0},
                        "description": "a plain torch MLP"}}


def tiny_config(tmp_path: Path, **changes) -> dict:
    data = {"run_id": "byo", "output_dir": str(tmp_path / "run"), "seed": 3, "methods": ["torch_mlp"],
            "foods": ["chocolate_balls"], "levels": ["low"], "trials": 1, "custom_methods": CUSTOM,
            "scoop": {"max_steps": 36, "min_steps": 12}, "transfer": {"pour_steps": 8, "settle_steps": 5},
            "executor": {"backend": "serial"}}
    return {**data, **changes}


def test_a_registered_torch_controller_is_evaluated_and_reported(tmp_path, capsys):
    path = tmp_path / "evaluate.yaml"
    path.write_text(yaml.safe_dump(tiny_config(tmp_path)))
    assert main(["evaluate", str(path), "--no-progress"]) == 0
    records = pd.read_parquet(tmp_path / "run" / "episodes.parquet")
    assert list(records["method"]) == ["torch_mlp"] and records["error"].fillna("").eq("").all()
    assert records["n_particles"].iloc[0] > 0 and pd.isna(records["rho"].iloc[0])
    saved = yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())
    assert saved["custom_methods"]["torch_mlp"]["controller"].endswith("torch_controller.py:TorchPolicyController")
    report = build_report(tmp_path / "run")
    fig5 = next(t for t in report.tables if t.key == "fig5_overall").data.set_index("method")
    assert fig5.loc["torch_mlp", "episodes"] == 1 and not fig5.loc["torch_mlp", "missing"]
    assert "torch_mlp" in (report.out_dir / "report.html").read_text()


def test_a_controller_that_cannot_be_imported_fails_at_load_naming_the_key(tmp_path):
    wrong = {"torch_mlp": {**CUSTOM["torch_mlp"], "controller": f"{EXAMPLE}:NoSuchController"}}
    with pytest.raises(ConfigError, match=r"custom_methods\.torch_mlp\.controller"):
        config_from_dict(EvaluationConfig, tiny_config(tmp_path, custom_methods=wrong))
    with pytest.raises(ConfigError, match="a name no built-in method has"):
        config_from_dict(EvaluationConfig, tiny_config(tmp_path, custom_methods={"grits": CUSTOM["torch_mlp"]}))
    with pytest.raises(ConfigError, match="methods"):
        config_from_dict(EvaluationConfig, tiny_config(tmp_path, custom_methods={}))


def test_an_entry_point_registers_a_method_for_every_config(tmp_path, monkeypatch):
    class EntryPoint:
        name, value = "torch_mlp", "tests.evaluation.test_custom_methods:ProtocolOnly"

    monkeypatch.setattr(custom_methods, "entry_points", lambda group: [EntryPoint()] if group == "grits_lab.methods" else [])
    config = config_from_dict(EvaluationConfig, tiny_config(tmp_path, custom_methods={}))
    assert config.methods == ["torch_mlp"]
    from grits_lab.evaluation.methods import build_controller, method_spec

    assert method_spec("torch_mlp", config).kind == "custom"
    assert isinstance(build_controller("torch_mlp", config, {}, lambda key, factory: factory()), ProtocolOnly)


class ProtocolOnly:
    cloud_steps = 0

    def reset(self, scene):
        pass

    def plan(self, history, scene):
        return None


def test_a_custom_food_from_a_foods_file_is_evaluated(tmp_path):
    from grits_lab.evaluation.evaluation_run import evaluate

    foods_file = Path(__file__).parents[2] / "examples" / "foods_custom.yaml"
    config = config_from_dict(EvaluationConfig, tiny_config(tmp_path, foods=["gummy_bears"], sim={"foods_file": str(foods_file)}))
    records = evaluate(config, progress=False)
    assert list(records["food"]) == ["gummy_bears"] and records["n_particles"].iloc[0] == 12  # the file's `low: {pieces: 12}`
    with pytest.raises(GritsError, match="gummy_bears"):  # the packaged library has no such food
        evaluate(config_from_dict(EvaluationConfig, tiny_config(tmp_path / "b", foods=["gummy_bears"])), progress=False)


def test_a_class_inside_the_package_is_not_a_custom_method(tmp_path):
    inside = {"torch_mlp": {"controller": "grits_lab.policies.rule_based:RuleBasedController"}}
    with pytest.raises(ConfigError, match="inside grits_lab"):
        config_from_dict(EvaluationConfig, tiny_config(tmp_path, custom_methods=inside))
