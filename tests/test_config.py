"""Config loading rejects bad input by key name; valid input round-trips."""

from __future__ import annotations

import dataclasses
import re
from typing import ClassVar, Literal, Optional

import pytest

from grits_lab.config import config_fingerprint, config_from_dict, config_to_dict, load_config, load_yaml, require
from grits_lab.errors import ConfigError


@dataclasses.dataclass
class InnerConfig:
    count: int = 3
    ratio: float = 0.5

    def __post_init__(self):
        require(self.count > 0, "count", self.count, "a positive integer")


@dataclasses.dataclass
class OuterConfig:
    name: str = "x"
    mode: Literal["fast", "slow"] = "fast"
    inner: InnerConfig = dataclasses.field(default_factory=InnerConfig)
    sizes: tuple[int, ...] = (1, 2)
    address: Optional[str] = None


def test_valid_mapping_builds_nested_dataclasses():
    cfg = config_from_dict(OuterConfig, {"mode": "slow", "inner": {"count": 7, "ratio": 1}, "sizes": [4, 5]})
    assert cfg.mode == "slow" and cfg.inner.count == 7 and cfg.inner.ratio == 1.0 and cfg.sizes == (4, 5)
    assert config_from_dict(OuterConfig, config_to_dict(cfg)) == cfg


@pytest.mark.parametrize(
    "data, fragment",
    [
        ({"inner": {"cuont": 1}}, "unknown key `inner.cuont`"),
        ({"inner": {"count": "three"}}, "`inner.count` must be an integer"),
        ({"inner": {"count": -1}}, "`inner.count` must be a positive integer. Got -1."),
        ({"mode": "medium"}, "`mode` must be one of 'fast', 'slow'"),
        ({"sizes": [1, "a"]}, "`sizes[1]` must be an integer"),
        ({"inner": 5}, "`inner` must be a mapping"),
        ({"name": True}, "`name` must be a string"),
    ],
)
def test_bad_values_name_the_key(data, fragment):
    with pytest.raises(ConfigError) as info:
        config_from_dict(OuterConfig, data)
    assert fragment in str(info.value)


def test_load_config_reports_file_and_yaml_errors(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "missing.yaml", OuterConfig)
    bad = tmp_path / "bad.yaml"
    bad.write_text("inner: [1, 2\n")
    with pytest.raises(ConfigError, match="invalid YAML"):
        load_config(bad, OuterConfig)
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text("inner:\n  count: 0\n")
    with pytest.raises(ConfigError, match=r"wrong.yaml: `inner.count` must be a positive integer"):
        load_config(wrong, OuterConfig)


@pytest.mark.parametrize("text, key, lines", [
    ("guidance: {rho: 2.5, s: 60}\nguidance: {rho: 8.0}\n", "guidance", (1, 2)),  # the field's case
    ("inner:\n  count: 1\n  ratio: 0.5\n  count: 2\n", "inner.count", (2, 4)),
    ("sizes: [{a: 1}, {a: 1, a: 2}]\n", "sizes[1].a", (1, 1)),
])
def test_a_key_given_twice_is_refused_naming_the_key_and_both_lines(tmp_path, text, key, lines):
    path = tmp_path / "override.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_yaml(path)
    assert str(info.value) == f"{path}: key `{key}` is given twice (lines {lines[0]} and {lines[1]}); give it once"


@pytest.mark.parametrize("text, key, line, value", [
    ("foods:\n  on: {}\n  yes: {}\n", "foods.on", 2, "True"),  # YAML 1.1 reads both as the boolean True
    ("levels:\n  low: 1\n  off: 2\n", "levels.off", 3, "False"),
    ("foods:\n  ~: {}\n", "foods.~", 2, "None"),
])
def test_a_key_that_yaml_reads_as_a_boolean_or_null_is_refused_naming_it_and_how_to_quote_it(tmp_path, text, key, line, value):
    path = tmp_path / "foods.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_yaml(path)
    assert str(info.value) == (f"{path}: key `{key}` (line {line}) is read by YAML as {value}, not as a name; "
                               f"quote it: \"{key.rsplit('.', 1)[-1]}\"")


def test_two_spellings_of_one_number_are_one_key_given_twice(tmp_path):
    path = tmp_path / "counts.yaml"
    path.write_text("counts:\n  10: a\n  0xa: b\n")
    with pytest.raises(ConfigError, match=r"key `counts.0xa` is given twice \(lines 2 and 3\)"):
        load_yaml(path)
    path.write_text('foods:\n  "on": {}\n  "yes": {}\n')
    assert load_yaml(path) == {"foods": {"on": {}, "yes": {}}}


@pytest.mark.parametrize("text, message", [
    ("inner:\n  ratio: .inf\n", "`inner.ratio` must be a finite number. Got inf."),
    ("inner:\n  ratio: -.inf\n", "`inner.ratio` must be a finite number. Got -inf."),
    ("inner:\n  ratio: .nan\n", "`inner.ratio` must be a finite number. Got nan."),
    ("inner:\n  count: 1000000000000000000000\n", "`inner.count` must be a 64-bit integer (magnitude below 2**63)."),
])
def test_a_number_no_config_can_use_is_refused_on_load_naming_the_key(tmp_path, text, message):
    path = tmp_path / "numbers.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(f"{path}: {message}")):
        load_config(path, OuterConfig)


def test_merge_keys_may_be_overridden_and_equal_text_of_other_types_are_two_keys(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text("base: &b {count: 1}\ninner:\n  <<: *b\n  count: 2\n1: a\n'1': b\n")
    assert load_yaml(path) == {"base": {"count": 1}, "inner": {"count": 2}, 1: "a", "1": "b"}


@dataclasses.dataclass
class RenamedConfig:
    retired_keys: ClassVar[dict[str, str]] = {"out": "output_dir"}

    output_dir: str = "here"
    inner: InnerConfig = dataclasses.field(default_factory=InnerConfig)


@dataclasses.dataclass
class HolderConfig:
    part: RenamedConfig = dataclasses.field(default_factory=RenamedConfig)


def test_a_retired_key_fails_in_one_line_naming_its_new_name(capsys):
    with pytest.raises(ConfigError, match=r"^`part.out` is retired; use `part.output_dir` \(docs/migration.md\)$"):
        config_from_dict(HolderConfig, {"part": {"out": "there"}})
    assert config_from_dict(RenamedConfig, {"output_dir": "there"}).output_dir == "there"
    with pytest.raises(ConfigError, match=r"unknown key `part.output`"):
        config_from_dict(HolderConfig, {"part": {"output": "a"}})
    with pytest.raises(ConfigError, match=r"unknown key `part.inner.out`"):  # retired keys are per dataclass
        config_from_dict(HolderConfig, {"part": {"inner": {"out": "a"}}})
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("kind, old, new, value", [
    ("demos", "output", "output_dir", "d"),
    ("spillage", "output", "output_dir", "d"),
    ("spillage", "trials", "episodes", 8),
])
def test_collection_configs_refuse_their_retired_keys(tmp_path, kind, old, new, value):
    from grits_lab.collection import load_collect_config

    path = tmp_path / "c.yaml"
    path.write_text(f"kind: {kind}\n{old}: {value}\n")
    with pytest.raises(ConfigError, match=rf"c.yaml: `{old}` is retired; use `{new}`"):
        load_collect_config(path)


def test_a_sweep_refuses_results_dir_naming_output_dir(tmp_path):
    from grits_lab.tune.study_config import load_study_config

    path = tmp_path / "s.yaml"
    path.write_text("study_name: s\nn_trials: 1\nevaluator: synthetic\nresults_dir: r\n"
                    "validation: {foods: [soybeans], levels: [low]}\n")
    with pytest.raises(ConfigError, match=r"`results_dir` is retired; use `output_dir`"):
        load_study_config(path)


def test_fingerprint_changes_with_values_only():
    a, b = OuterConfig(), OuterConfig()
    assert config_fingerprint(a) == config_fingerprint(b)
    assert config_fingerprint(a) != config_fingerprint(OuterConfig(name="y"))


def test_the_command_line_parser_imports_no_simulator_torch_or_ray():
    # `grits-lab --help` and one-line config errors should not wait seconds for heavy imports
    import subprocess
    import sys

    code = "import sys; from grits_lab.cli import build_parser; build_parser(); print(sorted(m for m in ('pybullet', 'torch', 'ray', 'open3d') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"
