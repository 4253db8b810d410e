"""What a result was made with: the CPU kernels label follows what NumPy, OpenBLAS and torch really dispatch to."""

from __future__ import annotations

import os
import subprocess
import sys

from grits_lab.versions import cpu_kernels, cpu_model

LABEL = "from grits_lab.versions import cpu_kernels; print(cpu_kernels())"


def _label(first: str = "", **env: str) -> str:
    """The label a fresh process prints, after running `first`."""
    out = subprocess.run([sys.executable, "-c", f"{first}\n{LABEL}"], env={**os.environ, **env}, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_the_label_names_numpy_blas_and_torch_whatever_the_process_imported_before():
    label = _label()
    assert label.startswith("numpy ") and "; openblas " in label and "; torch " in label
    assert _label("import torch") == label == cpu_kernels()  # a Ray worker and a serial run agree
    assert cpu_model() != ""


def test_forced_kernels_change_the_label():
    # OPENBLAS_CORETYPE and ATEN_CPU_CAPABILITY pick narrower kernels than the CPU offers; every x86-64 CPU with AVX runs them.
    forced = _label(OPENBLAS_CORETYPE="Sandybridge", ATEN_CPU_CAPABILITY="default")
    assert "; openblas Sandybridge; " in forced and forced.endswith("; torch DEFAULT")
    found = cpu_kernels().split(";")[0].removeprefix("numpy ")
    if found != "baseline":  # NumPy dispatches past its baseline here: switched off, its label says so
        assert _label(NPY_DISABLE_CPU_FEATURES=" ".join(found.split("+"))).startswith("numpy baseline;")


# --- what each version names --------------------------------------------------------------------

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def _digest(parts: dict) -> str:
    import hashlib
    import json

    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def env_fingerprint() -> str:
    """What the Gym env's id names: the world's settings, the packaged food library, the env's spaces
    and the scripted scoop's golden rollout (the world and the scoop, played)."""
    from grits_lab.config import config_to_dict
    from grits_lab.sim import gym_env
    from grits_lab.sim.foods import PACKAGED_FOODS
    from grits_lab.sim.sim_config import SimConfig

    return _digest({"sim": config_to_dict(SimConfig()), "foods": PACKAGED_FOODS.read_text(),
                    "spaces": [gym_env.ACTION_MODES, gym_env.RELATIVE_SCALE, gym_env.WORKSPACE[0].tolist(),
                               gym_env.WORKSPACE[1].tolist(), gym_env.MAX_TILT_RAD, gym_env.N_JOINTS],
                    "rollout": (ROOT / "tests" / "artifacts" / "expert_rollout.json").read_text()})


def protocol_fingerprint() -> str:
    """What the protocol names: the env, the scoop's and the later stages' settings, the record's
    columns and every golden record (which a change that moves a number in a record moves)."""
    from grits_lab.config import config_to_dict
    from grits_lab.policies.control import NO_HOOK_COLUMNS, ScoopSettings
    from grits_lab.records import RECORD_COLUMNS
    from grits_lab.task.transfer_settings import TransferSettings

    golden = {p.name: p.read_text() for p in sorted((ROOT / "tests" / "artifacts").glob("*.json"))}
    return _digest({"env": env_fingerprint(), "scoop": config_to_dict(ScoopSettings()),
                    "transfer": config_to_dict(TransferSettings()), "records": list(RECORD_COLUMNS),
                    "hook_columns": NO_HOOK_COLUMNS, "golden": golden})


def _check(name: str, version: int, recorded: dict[int, str], now: str) -> list[str]:
    """The rule for one version: the current version's recorded fingerprint is today's, and each
    version names something other than the one before it."""
    problems = []
    if max(recorded) != version:
        problems.append(f"{name} is {version} but its fingerprints end at {max(recorded)}")
    if recorded.get(version) != now:
        problems.append(f"what {name} {version} names changed (fingerprint {now}, recorded {recorded.get(version)!r}): "
                        f"bump {name} and record {now} for the new version (docs/protocol.md, \"When to bump\")")
    versions = sorted(recorded)
    problems += [f"{name} {b} names the same as {a} (fingerprint {recorded[b]}): a version moves only when what it names changes"
                 for a, b in zip(versions, versions[1:]) if recorded[a] == recorded[b]]
    return problems


def test_each_version_moves_when_what_it_names_changes_and_only_then():
    from grits_lab.versions import ENV_FINGERPRINTS, ENV_VERSION, PROTOCOL_FINGERPRINTS, PROTOCOL_VERSION

    problems = _check("ENV_VERSION", ENV_VERSION, ENV_FINGERPRINTS, env_fingerprint())
    problems += _check("PROTOCOL_VERSION", PROTOCOL_VERSION, PROTOCOL_FINGERPRINTS, protocol_fingerprint())
    assert problems == []


def test_the_version_rule_fails_a_silent_change_and_an_empty_bump():
    assert _check("V", 3, {3: "aa"}, "aa") == []
    assert "changed" in _check("V", 3, {3: "aa"}, "bb")[0]  # the thing changed, the version did not
    assert "names the same as 3" in _check("V", 4, {3: "aa", 4: "aa"}, "aa")[0]  # bumped, nothing changed
    assert "fingerprints end at 3" in " ".join(_check("V", 4, {3: "aa"}, "aa"))  # bumped, no fingerprint recorded

