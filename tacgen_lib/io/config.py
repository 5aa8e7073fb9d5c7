"""Configuration reading: the JSON schema's validation and defaults, and the settings reader.

Errors name the key as a dotted path (`align.taus[1]`) and the file, so a bad value stops the
run before any job starts with a message that says what to fix.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import os
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import yaml

if TYPE_CHECKING:  # jsonschema is imported where a config is validated (at parse time), not by
    # the jobs, which only read their settings (`settings_from`): ~0.1 s less per job
    import jsonschema

__all__ = [
    "ConfigError",
    "load_schema",
    "load_yaml",
    "schema_copy",
    "settings_from",
    "validate_schema",
]

T = TypeVar("T")


class ConfigError(ValueError):
    """The configuration is invalid; the message names the key."""


#: libyaml's C parser where PyYAML was built with it (the wheels are), else the pure-Python
#: one: the same safe YAML subset and the same values (tests/io/test_config.py checks every
#: config file of the repository), several times faster on the schema, which every Snakemake
#: start reads.
SAFE_LOADER: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_yaml(path: str | Path) -> Any:
    """The YAML file at `path` (safe subset: no Python objects), with `SAFE_LOADER`."""
    with open(path) as fh:
        return yaml.load(fh, Loader=SAFE_LOADER)  # noqa: S506 - a safe loader


def schema_copy(path: str | Path) -> Path:
    """Where the JSON copy of the schema at `path` lives (beside it; tools/config_reference.py
    writes it): ``{"source_sha256": <the YAML's bytes' sha256>, "schema": <the schema>}``."""
    return Path(path).with_suffix(".json")


def load_schema(path: str | Path) -> Any:
    """The YAML schema at `path`: from its JSON copy (`schema_copy`) where that copy was
    written from these very bytes, else parsed from the YAML (~30 ms with libyaml against
    ~0.3 ms for the copy: every job that builds a settings object reads the schema)."""
    raw = Path(path).read_bytes()
    try:
        copy_ = json.loads(schema_copy(path).read_text())
        if copy_.get("source_sha256") == hashlib.sha256(raw).hexdigest():
            return copy_["schema"]
    except (OSError, ValueError, AttributeError):
        pass
    return yaml.load(raw, Loader=SAFE_LOADER)  # noqa: S506 - a safe loader


#: (resolved schema path, mtime_ns, size) -> (schema, its validator): the fuzzed-config test and
#: the settings tests validate hundreds of configs against one schema; read it once per process
#: and again only when it changes. The schema is never mutated (`_fill_defaults` copies defaults).
_SCHEMAS: dict[tuple[str, int, int], tuple[dict, jsonschema.Draft202012Validator]] = {}


def _schema(path: str | Path) -> tuple[dict, jsonschema.Draft202012Validator]:
    resolved = os.path.realpath(path)
    stat = os.stat(resolved)
    key = (resolved, stat.st_mtime_ns, stat.st_size)
    if key not in _SCHEMAS:
        schema = load_schema(resolved)
        _SCHEMAS[key] = (schema, _validator_class()(schema))
    return _SCHEMAS[key]


def _validator_class() -> type[jsonschema.Draft202012Validator]:
    from jsonschema import Draft202012Validator

    return Draft202012Validator


def _key_path(parts) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def _fill_defaults(instance: Any, schema: Mapping, root: Mapping) -> None:
    """Set `default` values the schema declares for missing object keys (in place)."""
    if "$ref" in schema:
        ref = schema["$ref"].split("/")[-1]
        schema = root["$defs"][ref]
    if isinstance(instance, dict):
        for sub in schema.get("allOf", []):
            cond = sub.get("if")
            if cond is None or _validator_class()(cond).is_valid(instance):
                _fill_defaults(instance, sub.get("then", sub), root)
        for key, sub in schema.get("properties", {}).items():
            if isinstance(sub, dict):
                if key not in instance and "default" in sub:
                    instance[key] = copy.deepcopy(sub["default"])
                if key in instance:
                    _fill_defaults(instance[key], sub, root)
        extra = schema.get("additionalProperties")
        if isinstance(extra, dict):
            for key, value in instance.items():
                if key not in schema.get("properties", {}):
                    _fill_defaults(value, extra, root)


def _non_finite_numbers(node: Any, path: tuple = ()) -> list[tuple[tuple, float]]:
    """(key path, value) of the NaN and infinite numbers in a config tree (`.nan`, `.inf`)."""
    if isinstance(node, Mapping):
        return [p for k, v in node.items() for p in _non_finite_numbers(v, (*path, k))]
    if isinstance(node, list):
        return [p for i, v in enumerate(node) for p in _non_finite_numbers(v, (*path, i))]
    if isinstance(node, float) and not math.isfinite(node):
        return [(path, node)]
    return []


def validate_schema(config: dict, schema_path: str | Path, *, source: str = "config") -> dict:
    """Validate `config` in place against the schema and fill the defaults it declares.

    Raises ConfigError naming the key (e.g. `align.taus[0]: -0.1 is less than or equal to the
    minimum of 0`). NaN and infinity are refused everywhere: no setting takes them, and a
    JSON-schema bound such as `exclusiveMinimum: 0` lets `.inf` through. The cross-references
    a schema cannot see are checked above io (`tacgen_lib.workflow_config.validate_config`).
    """
    bad = _non_finite_numbers(config)
    if bad:
        lines = [f"{_key_path(p)}: {v!r} is not a finite number" for p, v in bad[:5]]
        raise ConfigError(f"{source}: invalid configuration\n  " + "\n  ".join(lines))
    schema, validator = _schema(schema_path)
    errors = sorted(
        validator.iter_errors(config),
        key=lambda e: (len(e.absolute_path), list(map(str, e.absolute_path))),
    )
    if errors:
        from jsonschema.exceptions import best_match

        err = best_match(errors)
        lines = [f"{_key_path(err.absolute_path)}: {err.message}"]
        lines += [f"{_key_path(e.absolute_path)}: {e.message}" for e in errors if e is not err][:4]
        raise ConfigError(f"{source}: invalid configuration\n  " + "\n  ".join(lines))
    _fill_defaults(config, schema, schema)
    return config


# --------------------------------------------------------------------------- settings reader


def settings_from(
    cls: type[T],
    section: Mapping[str, Any] | None,
    *,
    where: str,
    rename: Mapping[str, str] | None = None,
    ignore: Iterable[str] = (),
    **given: Any,
) -> T:
    """A settings dataclass from a config section: the one reader every settings object uses.

    Each field is read from its key (the key `io.schema.schema_fields` or `setting` gave it, or
    `rename`: field -> config key where the two differ) or taken from `given` (what the caller
    knows that is not config: a family's kind, a seed); a `io.schema.not_config` field is
    never read from the section.
    One rule for a missing key: the field keeps its default; a field without a default raises
    ConfigError naming `where.key`. A key that is neither a field's nor in `ignore` (keys of
    the section the rules read themselves, such as grids) raises ConfigError naming it. Values
    are coerced to the field's annotated type: int, float, str, bool, `tuple[X, ...]`,
    `tuple[X, Y]` and unions of those (the first member that fits: `int | str` reads 10 and
    "all"; a whole number given as 2.0 becomes 2; a bool is never a number). The schema stays
    the validator at start-up; this reader is what turns its checked sections into typed
    settings.
    """
    section = dict(section or {})
    ignore = {*ignore, *getattr(cls, "schema_skip", ())}  # keys `io.schema.schema_fields` skipped
    rename = {**_schema_renames(cls, where), **(rename or {})}
    hints = typing.get_type_hints(cls)
    names = [
        f.name for f in dataclasses.fields(cls) if f.metadata.get("config_key", "") is not None
    ]
    keys = {rename.get(n, n): n for n in names if n not in given}
    unknown = sorted(set(section) - set(keys) - set(ignore))
    if unknown:
        raise ConfigError(
            f"config {where}.{unknown[0]}: unknown key (known: {sorted(set(keys) | set(ignore))})"
        )
    values = dict(given)
    for f in dataclasses.fields(cls):
        if f.name in given or f.name not in names:
            continue
        key = rename.get(f.name, f.name)
        if key in section:
            values[f.name] = _coerce(hints[f.name], section[key], f"{where}.{key}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"config {where}.{key}: missing (this setting has no default)")
    try:
        return cls(**values)
    except ValueError as err:
        # a schema bound names the key under the class's schema section; one declaration
        # schema read at several places (a backbone, a probe family) names the place read
        section = getattr(cls, "schema_section", "")
        if section and section != where and str(err).startswith(f"{section}."):
            raise ValueError(where + str(err)[len(section) :]) from None
        raise


def _schema_renames(cls: type, where: str) -> dict[str, str]:
    """field -> config key of the fields from the schema (`io.schema.setting`) whose key, under
    section `where`, is not the field's name (``align.features`` for `feature`)."""
    out = {}
    for f in dataclasses.fields(cls):
        key = f.metadata.get("config_key")
        if key and key.startswith(f"{where}.") and key[len(where) + 1 :] != f.name:
            out[f.name] = key[len(where) + 1 :]
    return out


def _coerce(tp: Any, value: Any, where: str) -> Any:
    """`value` as the annotated type `tp` (see `settings_from`); other types pass unchanged."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for inner in [a for a in args if a is not type(None)]:  # the first type that fits
            try:
                return _coerce(inner, value, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(
            errors[0] if len(errors) == 1 else f"config {where}: {value!r} fits none of {args}"
        )
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"config {where}: {value!r} is not a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
        if not args:
            return tuple(value)
        if len(args) != len(value):
            raise ConfigError(f"config {where}: {value!r} needs {len(args)} items")
        return tuple(
            _coerce(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config {where}: {value!r} is not true or false")
        return value
    if tp in (int, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"config {where}: {value!r} is not a number")
        if tp is int:
            if float(value) != int(value):
                raise ConfigError(f"config {where}: {value!r} is not a whole number")
            return int(value)
        return float(value)
    if tp is str:
        if isinstance(value, Mapping | list | tuple):
            raise ConfigError(f"config {where}: {value!r} is not a text")
        return str(value)
    return value
