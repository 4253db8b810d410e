"""A lab's own controller, registered in the evaluation config or by an entry point, evaluated
through `grits-lab evaluate` and shown in the report, without editing the package."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from grits_lab.cli import main
from grits_lab.config import config_from_dict
from grits_lab.errors import ConfigError, GritsError, InputError
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


GUIDED = {"torch_mlp_guided": {"controller": f"{EXAMPLE}:GuidedTorchPolicyController", "options": {"hidden": 16, "seed": 0}}}


class FakeHistory:
    ee_pose = [np.array([0.45, 0.05, 0.30, 1, 0, 0, 0, 1, 0], dtype=np.float32)]


class FakeScene:
    def source_bowl_position(self):
        return np.array([0.50, 0.0, 0.10])


def test_a_guided_controller_is_built_with_the_guidance_rho_and_s_and_records_them(tmp_path):
    from grits_lab.evaluation.methods import build_controller, guidance_columns, guidance_gap

    config = config_from_dict(EvaluationConfig, tiny_config(tmp_path, methods=["torch_mlp_guided"], custom_methods=GUIDED,
                                                             guidance={"rho": 1.5, "s": 3}))
    controller = build_controller("torch_mlp_guided", config, {}, lambda key, factory: factory())
    assert (controller.rho, controller.s) == (1.5, 3)
    assert guidance_gap("torch_mlp_guided", config) is None and guidance_columns("torch_mlp_guided", config) == (1.5, 3)
    plain = config_from_dict(EvaluationConfig, tiny_config(tmp_path))
    assert "has no keyword arguments `rho` and `s`" in guidance_gap("torch_mlp", plain)
    with pytest.raises(ConfigError, match=r"custom_methods\.torch_mlp_guided\.options.*guidance\.rho"):
        wrong = {"torch_mlp_guided": {**GUIDED["torch_mlp_guided"], "options": {"rho": 2.0}}}
        config_from_dict(EvaluationConfig, tiny_config(tmp_path, methods=["torch_mlp_guided"], custom_methods=wrong))


def test_the_sweeps_entry_point_refuses_a_method_without_guidance_parameters_before_any_episode(tmp_path):
    from grits_lab.evaluation.evaluation_run import evaluate_guidance

    config = config_from_dict(EvaluationConfig, tiny_config(tmp_path))
    with pytest.raises(InputError, match="method 'torch_mlp' takes no guidance parameters: .*TorchPolicyController has no keyword"):
        evaluate_guidance(config, [], rho=1.0, s=3, method="torch_mlp")
    assert not (tmp_path / "run").exists()


def test_the_example_guided_controller_pulls_the_last_s_actions_toward_the_bowl_axis_by_rho_steps():
    cls = custom_methods.controller_class("torch_mlp_guided", custom_methods.CustomMethodConfig(**GUIDED["torch_mlp_guided"]))
    base = custom_methods.controller_class("torch_mlp", custom_methods.CustomMethodConfig(**CUSTOM["torch_mlp"]))
    unguided = base(hidden=16, seed=0).plan(FakeHistory(), FakeScene()).actions
    for rho, s in ((0.0, 8), (2.0, 0)):  # no strength, or no action corrected: exactly the policy's chunk
        np.testing.assert_array_equal(cls(rho, s, hidden=16, seed=0).plan(FakeHistory(), FakeScene()).actions, unguided)
    guided = cls(2.0, 3, hidden=16, seed=0)
    actions = guided.plan(FakeHistory(), FakeScene()).actions
    np.testing.assert_array_equal(actions[:5], unguided[:5])
    np.testing.assert_array_equal(actions[:, 2:], unguided[:, 2:])  # height and orientation untouched
    axis = np.array([0.50, 0.0])
    before = np.linalg.norm(unguided[5:, :2] - axis, axis=1)
    after = np.linalg.norm(actions[5:, :2] - axis, axis=1)
    np.testing.assert_allclose(before - after, 2.0 * guided.max_step, atol=1e-6)


def test_replay_gives_a_guided_controller_the_records_rho_and_s(tmp_path):
    from grits_lab.report.replay import load_run_config

    (tmp_path / "config.yaml").write_text(yaml.safe_dump(tiny_config(tmp_path, methods=["torch_mlp_guided"], custom_methods=GUIDED)))
    config = load_run_config(tmp_path, {"method": "torch_mlp_guided", "rho": 0.75, "s": 5})
    assert (config.guidance.rho, config.guidance.s) == (0.75, 5)


def test_two_controller_files_whose_paths_differ_only_by_slash_or_underscore_are_two_classes(tmp_path):
    from grits_lab.evaluation.custom_methods import CustomMethodConfig, controller_class

    files = {"first": tmp_path / "a_b" / "ctl.py", "second": tmp_path / "a" / "b_ctl.py"}
    for method, path in files.items():
        path.parent.mkdir(parents=True)
        path.write_text(f"class Ctl:\n    cloud_steps = 0\n    which = {method!r}\n"
                        "    def reset(self, scene): pass\n    def plan(self, history, scene): return None\n")
    classes = {m: controller_class(m, CustomMethodConfig(f"{p}:Ctl")) for m, p in files.items()}
    assert classes["first"].which == "first" and classes["second"].which == "second"


def test_a_controller_file_that_raises_while_loading_is_refused_and_loaded_afresh_once_fixed(tmp_path):
    from grits_lab.evaluation.custom_methods import CustomMethodConfig, controller_class

    path = tmp_path / "ctl.py"
    path.write_text("import not_a_module_anywhere\n")
    with pytest.raises(ConfigError, match=r"`custom_methods.mine.controller`: cannot import"):
        controller_class("mine", CustomMethodConfig(f"{path}:Ctl"))
    path.write_text("class Ctl:\n    cloud_steps = 0\n    def reset(self, scene): pass\n    def plan(self, history, scene): return None\n")
    assert controller_class("mine", CustomMethodConfig(f"{path}:Ctl")).cloud_steps == 0
