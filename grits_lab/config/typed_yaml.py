"""Build dataclass configs from YAML mappings, rejecting unknown keys and wrong types by name.

Every component config in grits_lab is a dataclass. `config_from_dict` walks its type hints so a
misspelled key or a string where a number belongs fails on load with one line that names the
dotted key, instead of surfacing as a confusing error deep inside a simulation or training run.
Range checks live in each dataclass's `__post_init__` (use `require`); before them, every float
must be finite (`.inf` and `.nan` are refused) and every integer must fit 64 bits.

A key that was renamed is refused by its new name: a dataclass declares `retired_keys:
ClassVar[dict[str, str]] = {old: new}`, and a mapping that still says `old` fails with one line
naming `new` (docs/migration.md).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

import yaml

from grits_lab.errors import ConfigError

T = TypeVar("T")
INT_LIMIT = 2**63  # every config integer lies in [-INT_LIMIT, INT_LIMIT)


def require(condition: bool, key: str, value: Any, expectation: str) -> None:
    """Raise ConfigError("`key` must be <expectation>. Got <value>.") unless `condition` holds."""
    if not condition:
        raise ConfigError(f"`{key}` must be {expectation}. Got {value!r}.")


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping; missing files and syntax errors become one-line ConfigErrors."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        data = parse_yaml(path.read_text(), path)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise ConfigError(f"{path}: invalid YAML{where}: {getattr(exc, 'problem', exc)}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: top level must be a mapping, got {type(data).__name__}")
    return data


def parse_yaml(text: str, source: str | Path) -> Any:
    """`yaml.safe_load(text)`, but a key given twice in one mapping is a ConfigError naming the
    dotted key and both lines (PyYAML would silently keep the last); `source` names the file."""
    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _refuse_repeated_keys(node, "", str(source), set(), loader)
        return loader.construct_document(node)
    finally:
        loader.dispose()


_NOT_NAMES = ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:null")  # plain `on`, `yes`, `off`, `~`, ...


def _refuse_repeated_keys(node: yaml.Node, prefix: str, source: str, visited: set[int], loader: yaml.SafeLoader) -> None:
    """ConfigError for a key given twice in one mapping, compared as the value YAML reads (`10` and
    `0xa` are one key), and for a plain key that YAML 1.1 reads as a boolean or null (`on`, `yes`,
    `off`, `~`): two foods `on` and `yes` would otherwise become one key True."""
    if id(node) in visited:  # an alias: already checked where its anchor stands
        return
    visited.add(id(node))
    if isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _refuse_repeated_keys(item, f"{prefix}[{i}]", source, visited, loader)
    elif isinstance(node, yaml.MappingNode):
        lines: dict[tuple[str, Any], int] = {}
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # `<<: *base`: its keys may be overridden here
                _refuse_repeated_keys(value_node, prefix, source, visited, loader)
                continue
            name = key_node.value if isinstance(key_node, yaml.ScalarNode) else repr(key_node.value)
            key = f"{prefix}.{name}" if prefix else str(name)
            line = key_node.start_mark.line + 1
            if isinstance(key_node, yaml.ScalarNode) and key_node.tag in _NOT_NAMES and not key_node.style:
                raise ConfigError(f"{source}: key `{key}` (line {line}) is read by YAML as "
                                  f"{loader.construct_object(key_node)}, not as a name; quote it: \"{name}\"")
            read = loader.construct_object(key_node) if isinstance(key_node, yaml.ScalarNode) else name
            if (key_node.tag, read) in lines:
                raise ConfigError(f"{source}: key `{key}` is given twice (lines {lines[key_node.tag, read]} and {line}); give it once")
            lines[key_node.tag, read] = line
            _refuse_repeated_keys(value_node, key, source, visited, loader)


def load_config(path: str | Path, cls: type[T]) -> T:
    """Load the YAML file at `path` into the dataclass `cls`, validating every key."""
    data = load_yaml(path)
    try:
        return config_from_dict(cls, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def config_from_dict(cls: type[T], data: Any, prefix: str = "") -> T:
    """Recursively build dataclass `cls` from a mapping; `prefix` is the dotted key path so far."""
    if not isinstance(data, dict):
        raise ConfigError(f"`{prefix or cls.__name__}` must be a mapping. Got {data!r}.")
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        key = f"{prefix}.{unknown[0]}" if prefix else unknown[0]
        renamed = getattr(cls, "retired_keys", {}).get(unknown[0])
        if renamed is not None:
            raise ConfigError(f"`{key}` is retired; use `{f'{prefix}.{renamed}' if prefix else renamed}` (docs/migration.md)")
        raise ConfigError(
            f"unknown key `{key}`; valid keys here: {', '.join(sorted(fields))}"
        )
    kwargs = {}
    for name, value in data.items():
        key = f"{prefix}.{name}" if prefix else name
        kwargs[name] = _coerce(hints[name], value, key)
    try:
        return cls(**kwargs)
    except TypeError as exc:  # a required field is missing
        raise ConfigError(f"`{prefix or cls.__name__}`: {exc}") from None
    except ConfigError as exc:  # a range check in __post_init__: name the key by its full path
        message = str(exc)
        if prefix and message.startswith("`") and not message.startswith(f"`{prefix}."):
            message = f"`{_joined(prefix, message[1:])}"
        raise ConfigError(message) from None


def _joined(prefix: str, key_and_rest: str) -> str:
    """`prefix` + the key a check named, without repeating the part they share: a check of
    TransferSettings names `transfer.clearance`; embedded as `exit.transfer` it is
    `exit.transfer.clearance`, not `exit.transfer.transfer.clearance`."""
    parts = prefix.split(".")
    for n in range(len(parts), 0, -1):
        shared = ".".join(parts[-n:]) + "."
        if key_and_rest.startswith(shared):
            return ".".join(parts[:-n] + [key_and_rest])
    return f"{prefix}.{key_and_rest}"


def _coerce(tp: Any, value: Any, key: str) -> Any:
    origin = get_origin(tp)
    args = get_args(tp)
    if tp is Any:
        return value
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(arg, value, key)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if len(errors) == 1 else f"`{key}` has an invalid value {value!r}.")
    if origin is Literal:
        if value not in args:
            choices = ", ".join(repr(a) for a in args)
            raise ConfigError(f"`{key}` must be one of {choices}. Got {value!r}.")
        return value
    if dataclasses.is_dataclass(tp):
        return config_from_dict(tp, value, key)
    if origin in (list, typing.Sequence) or tp is list:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"`{key}` must be a list. Got {value!r}.")
        item_tp = args[0] if args else Any
        return [_coerce(item_tp, v, f"{key}[{i}]") for i, v in enumerate(value)]
    if origin is tuple or tp is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"`{key}` must be a list. Got {value!r}.")
        if args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"`{key}` must have {len(args)} entries. Got {value!r}.")
            return tuple(_coerce(a, v, f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
        item_tp = args[0] if args else Any
        return tuple(_coerce(item_tp, v, f"{key}[{i}]") for i, v in enumerate(value))
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"`{key}` must be a mapping. Got {value!r}.")
        val_tp = args[1] if len(args) == 2 else Any
        return {k: _coerce(val_tp, v, f"{key}.{k}") for k, v in value.items()}
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"`{key}` must be true or false. Got {value!r}.")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"`{key}` must be an integer. Got {value!r}.")
        if not -INT_LIMIT <= value < INT_LIMIT:  # records and Parquet columns hold 64-bit integers
            raise ConfigError(f"`{key}` must be a 64-bit integer (magnitude below 2**63). Got {value!r}.")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"`{key}` must be a number. Got {value!r}.")
        if not math.isfinite(value):  # no config number means anything at inf or NaN
            raise ConfigError(f"`{key}` must be a finite number. Got {value!r}.")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"`{key}` must be a string. Got {value!r}.")
        return value
    return value


def merge_mappings(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """Recursive merge for config overrides: mappings merge key by key, anything else is replaced."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_mappings(out[key], value)
        else:
            out[key] = value
    return out


def config_to_dict(config: Any) -> Any:
    """Plain-YAML form of a config (dataclasses to dicts, tuples to lists)."""
    if dataclasses.is_dataclass(config):
        return {f.name: config_to_dict(getattr(config, f.name)) for f in dataclasses.fields(config)}
    if isinstance(config, (list, tuple)):
        return [config_to_dict(v) for v in config]
    if isinstance(config, dict):
        return {k: config_to_dict(v) for k, v in config.items()}
    if isinstance(config, Path):
        return str(config)
    return config


def config_changes(config: Any) -> dict[str, Any]:
    """Plain-YAML form of the fields of dataclass `config` that differ from its class's defaults."""
    defaults = type(config)()
    return {
        f.name: config_to_dict(getattr(config, f.name))
        for f in dataclasses.fields(config)
        if getattr(config, f.name) != getattr(defaults, f.name)
    }


def config_fingerprint(config: Any) -> str:
    """A short stable hash of a config, used to tell whether stored outputs match it."""
    text = json.dumps(config_to_dict(config), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
