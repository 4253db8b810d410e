"""Every config shipped in experiments/ and sweeps/ loads with its own loader (a stale key fails here)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _loader(path: Path):
    from grits_lab.config import load_config, load_yaml
    from grits_lab.collection.jobs import load_collect_config
    from grits_lab.evaluation.config import load_evaluation_config
    from grits_lab.pipeline.config import load_pipeline_config
    from grits_lab.policies.bc.training import load_bc_config
    from grits_lab.policies.diffusion.training import load_train_config
    from grits_lab.spillage.config import PredictorConfig
    from grits_lab.tune.config import load_study_config

    name = path.name
    if path.parent.name == "sweeps":
        return load_study_config
    data = load_yaml(path)
    if "stages" in data:
        return load_pipeline_config
    if data.get("kind") in ("demos", "spillage"):
        return load_collect_config
    if name.startswith("evaluate"):
        return load_evaluation_config
    if name.startswith("policy"):
        return load_train_config
    if name.startswith("bc"):
        return load_bc_config
    if name.startswith("predictor"):
        return lambda p: load_config(p, PredictorConfig)
    raise AssertionError(f"no loader known for {path}")


@pytest.mark.parametrize("path", sorted((ROOT / "experiments").glob("*.yaml")) + sorted((ROOT / "sweeps").glob("*.yaml")),
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_config_loads(path):
    assert _loader(path)(path) is not None


@pytest.mark.parametrize("guidance, fragment", [
    ({"threshold": 30}, "unknown key `guidance.threshold`"),
    ({"rho": -1.0}, "`guidance.rho` must be non-negative"),
    ({"s": -2}, "`guidance.s` must be at least -1"),
])
def test_the_evaluation_guidance_block_is_the_samplers_config_checked_by_key(guidance, fragment):
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.config import load_evaluation_config
    from grits_lab.sampling import GuidanceConfig

    path = ROOT / "experiments" / "evaluate_quick.yaml"
    assert isinstance(load_evaluation_config(path).guidance, GuidanceConfig)
    with pytest.raises(ConfigError, match="evaluate_quick.yaml: ") as info:
        load_evaluation_config(path, {"guidance": guidance})
    assert fragment in str(info.value)
