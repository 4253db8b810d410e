"""The method registry: every method of the paper by name, with the checkpoints it needs and how to build its scoop controller.

A method is a recipe, not a model: `build_controller(name, config, cache)` loads the checkpoints
the method needs (through `cache`, so that a worker loads each file once for all its episodes)
and returns a scoop controller (grits_lab/evaluation/controllers.py protocol). The diffusion
methods share one trained policy and differ only in the sampler and the predictor checkpoint,
so a difference between dp, dp_post and grits on the same seed is the guidance's alone.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from grits_lab.errors import ConfigError, StorageError
from grits_lab.records import CPU_KERNELS

if TYPE_CHECKING:  # annotations only
    from grits_lab.evaluation.evaluation_config import CheckpointPaths, EvaluationConfig
    from grits_lab.policies.control import Controller


@dataclass(frozen=True)
class MethodSpec:
    """kind: which controller family; predictor: which predictor checkpoint key (None: no predictor);
    sampler: "plain", "guided" or "posthoc" for the diffusion family."""

    kind: str
    checkpoints: tuple[str, ...]
    predictor: str | None = None
    sampler: str = "plain"
    description: str = ""


METHODS: dict[str, MethodSpec] = {
    "expert": MethodSpec("expert", (), description="the scripted expert's scoop (the demonstrations' own): an oracle for the stages after it"),
    "rule_based": MethodSpec("rule_based", (), description="centre, measure food height, dig 5 cm, fixed scoop"),
    "bc": MethodSpec("bc", ("bc",), description="behavior cloning: encoder features -> MLP -> actions"),
    "scone": MethodSpec("scone", ("demos",), description="SCONE-style: probe, then a scoop conditioned on the probe"),
    "dp": MethodSpec("diffusion", ("policy",), description="Diffusion Policy, unguided"),
    "dp_post": MethodSpec("diffusion", ("policy", "predictor"), "predictor", "posthoc", "Diffusion Policy (Post.)"),
    "grits": MethodSpec("diffusion", ("policy", "predictor"), "predictor", "guided", "GRITS: composite cloud + DP3 predictor"),
    "grits_raw": MethodSpec("diffusion", ("policy", "predictor_raw"), "predictor_raw", "guided", "GRITS, predictor on raw clouds"),
    "grits_pointnet2": MethodSpec("diffusion", ("policy", "predictor_pointnet2"), "predictor_pointnet2", "guided", "GRITS, PointNet++ predictor"),
    "grits_horizon": MethodSpec("diffusion", ("policy", "predictor_horizon"), "predictor_horizon", "guided",
                                "GRITS, predictor trained on horizon labels (what a chunk leads to until delivery)"),
}


def method_spec(name: str, config: EvaluationConfig | None = None) -> MethodSpec:
    """The spec of a built-in method, or of a registered controller (`config.custom_methods`, or an
    entry point: grits_lab/evaluation/custom_methods.py), which needs no checkpoint of ours.
    KeyError for a name neither knows."""
    from grits_lab.evaluation.custom_methods import registered_methods

    if name in METHODS:
        return METHODS[name]
    custom = registered_methods(config.custom_methods if config is not None else None)[name]
    return MethodSpec("custom", (), description=custom.description or custom.controller)


def method_checkpoints(name: str, checkpoints: CheckpointPaths) -> dict[str, str]:
    """{key: path} of the files `name` needs; a missing or unset one is a ConfigError naming it."""
    if name not in METHODS:
        return {}  # a registered controller loads its own files
    spec = METHODS[name]
    out = {}
    for key in spec.checkpoints:
        path = getattr(checkpoints, key)
        if not path:
            raise ConfigError(f"method {name!r} needs `checkpoints.{key}`; set it in the evaluation config")
        if not Path(path).exists():
            raise StorageError(f"method {name!r}: `checkpoints.{key}` not found: {path} (train it first)")
        out[key] = str(path)
    return out


# Top-level checkpoint entries that are training state, not the model a method runs.
_TRAINING_STATE = ("optimizer", "lr_scheduler", "torch_rng_processes")


def weights_digest(path: str | Path) -> str | None:
    """First 16 hex digits of the SHA-256 of a checkpoint's arrays (weights, EMA weights, normalizers:
    every torch tensor and NumPy array, by its place in the file, dtype and shape), leaving out the
    training state and everything else (paths, configs, history). Two files from the same training
    on other paths have the same weights digest and different file digests. None for a directory."""
    return checkpoint_identity(path)["weights_sha256_16"]


def checkpoint_identity(path: str | Path) -> dict[str, str | None]:
    """What a file digest cannot tell, from one read of the checkpoint's bytes: `weights_sha256_16`
    (`weights_digest`) and `trained on cpu kernels` (its `cpu_kernels`, grits_lab/versions.py; None
    when written before it was recorded). Both None for a directory. The bytes are parsed by the
    tensors-only loader every method uses (grits_lab/training/checkpoints.py): a file holding any
    other object is refused with InputError and nothing in it runs."""
    import torch

    from grits_lab.training.checkpoints import load_checkpoint

    path = Path(path)
    if path.is_dir():
        return {"weights_sha256_16": None, "trained on cpu kernels": None}
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StorageError(f"cannot read checkpoint {path}: {exc.strerror or exc}") from None
    checkpoint = load_checkpoint(path, data=data)
    digest = hashlib.sha256()

    def visit(value: Any, where: str) -> None:
        if isinstance(value, torch.Tensor):
            value = value.detach().cpu().contiguous().numpy()
        if isinstance(value, np.ndarray):
            digest.update(f"{where}:{value.dtype}:{value.shape};".encode())
            digest.update(np.ascontiguousarray(value).tobytes())
        elif isinstance(value, dict):
            for key in sorted(value, key=str):
                if not (where == "" and key in _TRAINING_STATE):
                    visit(value[key], f"{where}/{key}")
        elif isinstance(value, (list, tuple)):
            for i, item in enumerate(value):
                visit(item, f"{where}[{i}]")

    visit(checkpoint, "")
    kernels = checkpoint.get(CPU_KERNELS) if isinstance(checkpoint, dict) else None
    return {"weights_sha256_16": digest.hexdigest()[:16], "trained on cpu kernels": str(kernels) if kernels else None}


def file_digest(path: str | Path) -> str:
    """First 16 hex digits of the SHA-256 of a file, or of a directory's index (datasets)."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        for p in sorted(path.rglob("*")):
            if p.is_file() and p.suffix in (".parquet", ".yaml", ".npz"):
                digest.update(f"{p.relative_to(path)}:{p.stat().st_size};".encode())
    else:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()[:16]


GUIDED_METHODS = tuple(name for name, spec in METHODS.items() if spec.sampler == "guided")


def guidance_gap(name: str, config: EvaluationConfig) -> str | None:
    """None when method `name` takes its guidance (rho, s) from `config.guidance`: a guided built-in,
    or a registered controller whose class takes keyword arguments `rho` and `s`
    (grits_lab/evaluation/custom_methods.py). Otherwise what it lacks, worded to follow the name."""
    from grits_lab.evaluation.custom_methods import controller_class, missing_guidance_parameters, registered_methods

    if name in METHODS:
        if METHODS[name].sampler == "guided":
            return None
        return f"takes no guidance parameters: of the built-in methods only {', '.join(GUIDED_METHODS)} sample with `guidance`"
    custom = registered_methods(config.custom_methods)
    if name not in custom:
        return (f"is no method: neither built-in ({', '.join(METHODS)}) nor registered "
                "(`custom_methods`, or a `grits_lab.methods` entry point)")
    missing = missing_guidance_parameters(controller_class(name, custom[name]))
    if not missing:
        return None
    named = " and ".join(f"`{m}`" for m in missing)
    return f"takes no guidance parameters: {custom[name].controller} has no keyword argument{'s' if len(missing) > 1 else ''} {named}"


def guidance_columns(name: str, config: EvaluationConfig) -> tuple[float, int]:
    """(rho, s) recorded for a method: `guidance`'s for a guided one (guidance_gap), NaN / -1 for methods without guidance."""
    spec = method_spec(name, config)
    if spec.sampler == "guided" or (spec.kind == "custom" and guidance_gap(name, config) is None):
        return float(config.guidance.rho), int(config.guidance.s)
    if spec.sampler == "posthoc":
        return float(config.posthoc.rho), -1
    return math.nan, -1


def build_controller(name: str, config: EvaluationConfig, paths: dict[str, str],
                     cache: Callable[[Any, Callable[[], Any]], Any],
                     noise_keys: Callable[[int], tuple[object, ...]] | None = None) -> Controller:
    """The scoop controller of method `name`; `cache(key, factory)` keeps loaded models per worker;
    `noise_keys(plan)`: the keys of a sampling controller's plan noise (`ScoopHook.noise_keys`; None:
    ("plan", plan))."""
    from grits_lab.evaluation import controllers

    spec = method_spec(name, config)
    if spec.kind == "custom":
        from grits_lab.evaluation.custom_methods import build_custom_controller, registered_methods

        return build_custom_controller(name, registered_methods(config.custom_methods)[name], config.guidance)
    if spec.kind == "expert":
        return controllers.ExpertController()
    if spec.kind == "rule_based":
        from grits_lab.policies.rule_based import RuleBasedController

        return RuleBasedController(config.rule_based)
    if spec.kind == "bc":
        from grits_lab.policies.bc import BCPolicy

        policy = cache(("bc", paths["bc"]), lambda: BCPolicy.load(paths["bc"]))
        return controllers.BCController(policy)
    if spec.kind == "scone":
        from grits_lab.policies.scone import SconeController, scoop_prior

        prior = cache(("scone-prior", paths["demos"]), lambda: scoop_prior(paths["demos"]))
        return SconeController(config.scone, prior)
    from grits_lab.policies.diffusion import DiffusionPolicy

    policy = cache(("dp", paths["policy"]), lambda: DiffusionPolicy.load(paths["policy"]))
    predictor = None
    if spec.predictor is not None:
        from grits_lab.spillage import load_predictor

        key = spec.predictor
        predictor = cache(("predictor", paths[key]), lambda: load_predictor(paths[key]))
    return controllers.DiffusionController(
        policy, predictor, spec.sampler, config.guidance, config.posthoc,
        raw_cloud=(spec.predictor == "predictor_raw"), noise_keys=noise_keys,
    )


def check_method_checkpoints(name: str, paths: dict[str, str], guidance: Any = None) -> None:
    """Before the first episode: each checkpoint of method `name` is the kind its key says, a
    predictor judges chunks as long as the policy executes, and `guidance.s` (when `guidance` is
    given and the method is guided) lies on the policy's training-step scale, at most its
    `num_train_timesteps` (ConfigError naming the keys otherwise)."""
    from grits_lab.config import config_from_dict
    from grits_lab.training import load_checkpoint

    n_action_steps = None
    for key, path in paths.items():
        if key == "demos":  # a dataset directory, read by its own loader (arrays only, never a pickle)
            if not Path(path).is_dir():
                raise ConfigError(f"`checkpoints.demos` must be a demonstrations dataset directory (`grits-lab collect`), "
                                  f"not a file: {path}")
            continue
        ckpt = load_checkpoint(path)
        state = ckpt.get("policy") if isinstance(ckpt, dict) else None
        if key == "policy" or key == "bc":
            want_bc = key == "bc"
            if not isinstance(state, dict) or (state.get("kind") == "bc") != want_bc:
                kind = "behavior-cloning" if want_bc else "diffusion policy"
                raise ConfigError(f"`checkpoints.{key}` is not a {kind} checkpoint: {path}")
            if key == "policy":
                from grits_lab.policies.diffusion import DiffusionPolicyConfig

                try:
                    policy_config = config_from_dict(DiffusionPolicyConfig, state["config"])
                except (ConfigError, KeyError, TypeError):
                    raise ConfigError(f"`checkpoints.policy` is not a diffusion policy checkpoint: {path}") from None
                n_action_steps = policy_config.n_action_steps
                steps = policy_config.scheduler.num_train_timesteps
                if guidance is not None and name in GUIDED_METHODS and guidance.s > steps:
                    raise ConfigError(f"`guidance.s` is {guidance.s}, but the policy of `checkpoints.policy` trained on "
                                      f"{steps} timesteps: s is on that scale (steps with t <= s are guided), at most {steps}")
    spec = METHODS.get(name)
    if spec is None or spec.predictor is None:
        return
    from grits_lab.data.format import CHUNK_KEY
    from grits_lab.spillage.predictor_checkpoint import read_checkpoint
    from grits_lab.spillage.predictor_config import PredictorModelConfig

    try:
        stored = read_checkpoint(paths[spec.predictor])["config"]["model"]  # read_checkpoint refuses a retired key name
        chunk = int(stored.get(CHUNK_KEY, PredictorModelConfig.n_action_steps))  # the default, for a config stored without it
    except StorageError:
        raise ConfigError(f"`checkpoints.{spec.predictor}` is not a spillage predictor checkpoint: {paths[spec.predictor]}") from None
    except (KeyError, TypeError, ValueError, AttributeError):
        chunk = PredictorModelConfig.n_action_steps
    if n_action_steps is not None and chunk != n_action_steps:
        raise ConfigError(
            f"`checkpoints.{spec.predictor}` judges chunks of {chunk} actions, but the policy of "
            f"`checkpoints.policy` executes {n_action_steps} (n_action_steps); train the predictor with "
            f"`model.n_action_steps: {n_action_steps}` on a dataset collected with `n_action_steps: {n_action_steps}`"
        )
