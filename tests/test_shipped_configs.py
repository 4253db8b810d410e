"""Every config shipped in experiments/, sweeps/ and studies/*/configs/ loads with its own loader (a stale key fails here)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"
# Every stage config shipped: the presets, then the studies' own.
SHIPPED = sorted((ROOT / "experiments").glob("*.yaml")) + sorted(STUDIES.glob("*/configs/*.yaml"))


def _loaders() -> dict:
    """Every stage's config loader, by the kind of config it reads."""
    from grits_lab.config import load_config
    from grits_lab.collection.jobs import load_collect_config
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.pipeline.pipeline_config import load_pipeline_config
    from grits_lab.policies.bc.training_bc import load_bc_config
    from grits_lab.policies.diffusion.training_diffusion import load_train_config
    from grits_lab.spillage.predictor_config import PredictorConfig
    from grits_lab.tune.study_config import load_study_config

    return {"sweep": load_study_config, "pipeline": load_pipeline_config, "collect": load_collect_config,
            "evaluation": load_evaluation_config, "policy": load_train_config, "bc": load_bc_config,
            "predictor": lambda p: load_config(p, PredictorConfig), "scoop_convergence": _convergence}


def _convergence(path: Path):
    """A scoop-convergence study config: its settings' evaluation configs load too."""
    from studies.scoop_convergence.convergence import evaluation_configs, load_convergence_config

    return evaluation_configs(load_convergence_config(path), ROOT / "results" / "unused")


def _kind(path: Path) -> str:
    """The one kind of config `path` is, told by which loader accepts it (never by its file name):
    "override" when none does alone and it loads merged onto the protocol's evaluation config (a
    study's change of the transfer, the world, the guide or the runs' names). AssertionError when
    two loaders accept it (an ambiguous config) or none does even merged."""
    from grits_lab.config import load_yaml
    from grits_lab.errors import GritsError
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    accepted = []
    for kind, load in _loaders().items():
        try:
            load(path)
        except GritsError:
            continue
        accepted.append(kind)
    assert len(accepted) <= 1, f"{path} loads as {accepted}: a config is one kind"
    if accepted:
        return accepted[0]
    load_evaluation_config(ROOT / "experiments" / "evaluate_cpu.yaml", dict(load_yaml(path)))  # raises naming the key
    return "override"


def _loader(path: Path):
    from grits_lab.config import load_yaml
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    kind = _kind(path)
    if kind == "override":
        return lambda p: load_evaluation_config(ROOT / "experiments" / "evaluate_cpu.yaml", dict(load_yaml(p)))
    return _loaders()[kind]


@pytest.mark.parametrize("path", SHIPPED + sorted((ROOT / "sweeps").glob("*.yaml")), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_config_loads(path):
    assert _loader(path)(path) is not None


def test_the_previous_transfer_override_and_the_oracle_use_seeds_no_evaluation_uses():
    from grits_lab.config import load_yaml
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    previous = load_evaluation_config(ROOT / "experiments" / "evaluate_cpu.yaml", dict(load_yaml(STUDIES / "post_scoop_losses" / "configs" / "transfer_previous.yaml")))
    assert (previous.transfer.profile, previous.transfer.rest_pull, previous.transfer.slow_to_limits) == ("constant", True, False)
    assert previous.transfer.interpolation == "linear" and previous.transfer.ik_refine is False  # scoop-v8's motion and v9's IK
    assert previous.transfer.heading_free_lift is False  # scoop-v10's options
    oracle = load_evaluation_config(ROOT / "experiments" / "oracle_transfer.yaml")
    assert oracle.methods == ["expert"] and len(oracle.foods) == 16
    used = {load_evaluation_config(p).seed for p in SHIPPED if p.name.startswith("evaluate")}
    used |= {load_yaml(p).get("validation", {}).get("seed") for p in (ROOT / "sweeps").glob("*.yaml")}
    assert oracle.seed not in used


@pytest.mark.parametrize("name", ["dp_rollouts_train.yaml", "dp_rollouts_brim.yaml"])  # studies/brim_guidance/configs
def test_the_policys_training_rollouts_are_on_training_foods_and_seeds_nothing_else_uses(name):
    from grits_lab.config import load_yaml
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.sim.foods import load_foods

    rollouts = load_evaluation_config(STUDIES / "brim_guidance" / "configs" / name)
    assert rollouts.methods == ["dp"] and rollouts.rollout_chunks
    assert set(rollouts.foods) <= set(load_foods().names("train"))
    others = [p for p in SHIPPED if not p.name.startswith("dp_rollouts_")]

    def episodes(config):  # (food, level, episode seed) of every episode an evaluation config plays
        return {(k.food, k.level, k.seed) for k in config.keys(load_foods(config.sim.foods_file))}

    played = set().union(*(episodes(load_evaluation_config(p)) for p in others if "methods" in load_yaml(p)))
    assert not episodes(rollouts) & played  # an evaluation may share the root seed (other trials), not an episode
    used = {load_yaml(p).get("validation", {}).get("seed") for p in (ROOT / "sweeps").glob("*.yaml")}
    used |= {load_yaml(p).get("seed") for p in others if "kind" in load_yaml(p)}  # datasets
    assert rollouts.seed not in used
    # the rollout sets share a root seed but no level, so no episode (food, level, seed) twice
    levels = [set(load_evaluation_config(p).levels) for p in STUDIES.glob("*/configs/dp_rollouts_*.yaml")]
    assert sum(len(x) for x in levels) == len(set().union(*levels))


@pytest.mark.parametrize("guidance, fragment", [
    ({"threshold": 30}, "unknown key `guidance.threshold`"),
    ({"rho": -1.0}, "`guidance.rho` must be non-negative"),
    ({"s": -2}, "`guidance.s` must be at least -1"),
])
def test_the_evaluation_guidance_block_is_the_samplers_config_checked_by_key(guidance, fragment):
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.sampling import GuidanceConfig

    path = ROOT / "experiments" / "evaluate_quick.yaml"
    assert isinstance(load_evaluation_config(path).guidance, GuidanceConfig)
    with pytest.raises(ConfigError, match="evaluate_quick.yaml: ") as info:
        load_evaluation_config(path, {"guidance": guidance})
    assert fragment in str(info.value)


def _stage_configs_with_a_sim_block() -> list[tuple[Path, str]]:
    """(shipped stage config, dotted key of its sim block): evaluations, collections, policy trainings."""
    from grits_lab.config import load_yaml

    out = []
    for path in SHIPPED:
        kind = _kind(path)
        if kind in ("evaluation", "collect"):
            out.append((path, "sim"))
        elif kind == "policy":
            out.append((path, "rollout.sim"))
    return out


@pytest.mark.parametrize("path, block", _stage_configs_with_a_sim_block(), ids=lambda v: v.name if isinstance(v, Path) else v)
def test_a_misspelled_sim_key_in_a_shipped_stage_config_fails_at_load_naming_it(tmp_path, path, block):
    import yaml

    from grits_lab.config import load_yaml
    from grits_lab.errors import ConfigError

    data = load_yaml(path)
    node = data
    for part in block.split("."):
        node = node.setdefault(part, {})
    node["time_stpe"] = 0.005
    bad = tmp_path / path.name
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as info:
        _loader(path)(bad)
    assert f"unknown key `{block}.time_stpe`" in str(info.value)


def test_datasets_collected_before_are_recognized_by_their_config_or_refused_by_the_chunk_lengths_old_name(tmp_path):
    """Fingerprints stored by datasets collected before the sim block was typed (`sim: {}`): a demos
    dataset still matches its config and resumes. A spillage dataset of then calls the chunk length
    `chunk_len` (before scoop-v4): it is refused in one line naming its manifest and the key, never
    resumed; a dataset of another config is still refused."""
    import yaml

    from grits_lab.collection.driver import existing_manifest
    from grits_lab.collection.jobs import load_collect_config
    from grits_lab.config import config_fingerprint
    from grits_lab.data.format import MANIFEST_FILE
    from grits_lab.errors import ConfigError, StorageError

    stored = {"demos_paper.yaml": "44337bd0841efe53", "demos_cpu.yaml": "66784ff117cfd6ad", "demos_quick.yaml": "deaee82b43f607c7",
              "spillage_paper.yaml": "e6847f2aed697ab6", "spillage_cpu.yaml": "e572800d4c39c388", "spillage_quick.yaml": "4e44dd76c6349ce0"}
    for name, fingerprint in stored.items():
        config = load_collect_config(ROOT / "experiments" / name)
        assert config.identity()["sim"] == {}
        folder = tmp_path / name
        folder.mkdir()
        identity = config.identity()
        if config.kind == "spillage":
            identity["chunk_len"] = identity.pop("n_action_steps")  # the manifest's config as it was stored
        (folder / MANIFEST_FILE).write_text(yaml.safe_dump({"kind": config.kind, "fingerprint": fingerprint, "config": identity}))
        if config.kind == "demos":
            assert existing_manifest(folder, config.kind, config.identity())["fingerprint"] == fingerprint
            continue
        with pytest.raises(ConfigError, match=rf"^{folder / MANIFEST_FILE}: `chunk_len` is the chunk length's name before "
                                              r"scoop-v4, .*; collect it again under the current protocol: choose another output "
                                              r"or remove it \(docs/migration.md\)$"):
            existing_manifest(folder, config.kind, config.identity())
    current = load_collect_config(ROOT / "experiments" / "spillage_cpu.yaml")
    (tmp_path / "spillage_cpu.yaml" / MANIFEST_FILE).write_text(yaml.safe_dump(
        {"kind": "spillage", "fingerprint": config_fingerprint(current.identity()), "config": current.identity()}))
    assert existing_manifest(tmp_path / "spillage_cpu.yaml", "spillage", current.identity())["kind"] == "spillage"
    with pytest.raises(StorageError, match="different config"):
        existing_manifest(tmp_path / "spillage_cpu.yaml", "spillage", load_collect_config(ROOT / "experiments" / "spillage_quick.yaml").identity())


def test_an_evaluation_config_with_a_sim_override_round_trips_through_its_yaml_form():
    from grits_lab.config import config_from_dict, config_to_dict
    from grits_lab.evaluation.evaluation_config import EvaluationConfig, load_evaluation_config

    config = load_evaluation_config(ROOT / "experiments" / "evaluate_quick.yaml",
                                    {"sim": {"time_step": 0.005, "cameras": [{"name": "front", "eye": [1, 0, 0.6], "target": [0.5, 0, 0]}]}})
    assert config.sim.time_step == 0.005 and config.sim.cameras[0].eye == (1.0, 0.0, 0.6)
    assert config_from_dict(EvaluationConfig, config_to_dict(config)) == config


@pytest.mark.parametrize("name, count, digest", [
    ("evaluate_paper.yaml", 100, "7bccbf48c17cd090"),
    ("evaluate_cpu.yaml", 100, "7bccbf48c17cd090"),
    ("evaluate_quick.yaml", 10, "33fb0e54b82bec26"),
])
def test_shipped_evaluations_keep_their_episodes_and_seeds(name, count, digest):
    """Digests of [[food, level, trial, seed], ...] from before the episode grid was shared with the sweep."""
    import hashlib
    import json

    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.evaluation.evaluation_run import episode_keys

    rows = [[k.food, k.level, k.trial, k.seed] for k in episode_keys(load_evaluation_config(ROOT / "experiments" / name))]
    assert len(rows) == count and hashlib.sha256(json.dumps(rows).encode()).hexdigest()[:16] == digest


def test_a_sweeps_validation_block_as_an_evaluation_config_gives_the_same_episodes():
    from grits_lab.config import load_yaml
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.evaluation.evaluation_run import episode_keys
    from grits_lab.tune.study_config import load_study_config

    sweep = ROOT / "sweeps" / "grits_quick.yaml"
    validation = load_yaml(sweep)["validation"]
    evaluation = load_evaluation_config(ROOT / "experiments" / "evaluate_quick.yaml", validation)
    assert episode_keys(evaluation) == load_study_config(sweep).episodes()
