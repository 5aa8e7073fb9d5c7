"""The configuration schema as the one statement of each setting: settings fields read from it.

config/config.schema.yaml states each setting's default, type, bounds and meaning. A stage's
settings dataclass takes a field per key of its config section from it (`schema_fields`: the
field's type from the key's schema, its default the schema's, read once per process, lists as
tuples, a ``number`` as a float), or declares one with `setting("align.epochs")`; and
`check_settings` holds a value to the schema's type and bounds, naming the config key. A field
that is not a config key (what a caller knows: a family's kind, a seed) says so with
`not_config`, so that a test can require every other field to be a key of the schema with the
schema's default.

The checker here covers the JSON-schema keywords the settings' keys use (types, bounds, enums,
list lengths and items); a keyword it does not know stops `check_settings` rather than pass
silently. It is its own so that a job, which builds settings objects, need not import
jsonschema (tens of ms at every start); tests/io/test_schema_settings.py holds its verdicts
equal to jsonschema's on every settings key. The whole config is validated by jsonschema at start-up (`io.config.validate_schema`);
this is what a settings object built in code (`tiny()`, `replace`) is held to.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import operator
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal, Self, TypeVar

from tacgen_lib.io.config import load_schema, settings_from

__all__ = [
    "SCHEMA_PATH",
    "SchemaSettings",
    "check_settings",
    "config_key",
    "config_schema",
    "not_config",
    "schema_fields",
    "schema_node",
    "schema_type",
    "setting",
]

#: The schema of the repository's configuration (tacgen_lib sits beside config/).
SCHEMA_PATH = Path(__file__).resolve().parents[2] / "config" / "config.schema.yaml"

#: Keywords that state no bound (what a setting means, its default).
_ANNOTATIONS = frozenset({"description", "default", "title", "$comment"})

#: The metadata key of a settings field: its dotted config key, or None (not a config key).
_KEY = "config_key"

C = TypeVar("C", bound=type)


@functools.cache
def config_schema() -> Mapping[str, Any]:
    """The schema (config/config.schema.yaml), read once per process (`io.config.load_schema`)."""
    return load_schema(SCHEMA_PATH)


def schema_node(key: str) -> Mapping[str, Any]:
    """The schema of dotted config key `key` (``probes.robustness.mlp.folds``); ``*`` stands
    for any name of a mapping of declarations (``probes.families.*.kind``); a key that starts
    with ``$defs.NAME`` is read in the schema's definition NAME (``$defs.simulated_corpus.n``:
    a declaration whose place in the config has a name of the user's, ``corpora.<name>``).

    Raises KeyError naming the key where the schema has no such property.
    """
    root = config_schema()
    node: Mapping[str, Any] = root
    parts = key.split(".")
    if parts[0] == "$defs":
        if len(parts) < 2 or parts[1] not in root.get("$defs", {}):
            raise KeyError(f"config/config.schema.yaml has no definition {key!r}")
        node, parts = root["$defs"][parts[1]], parts[2:]
    for part in parts:
        if "$ref" in node:
            node = root["$defs"][node["$ref"].split("/")[-1]]
        props = node.get("properties", {})
        if part == "*" and isinstance(node.get("additionalProperties"), Mapping):
            node = node["additionalProperties"]
            continue
        if part not in props:
            raise KeyError(f"config/config.schema.yaml has no key {key!r}")
        node = props[part]
    return node


def _as_python(value: Any, spec: Mapping[str, Any]) -> Any:
    """A schema default as a settings value: lists as tuples, a ``number`` as a float."""
    if isinstance(value, list):
        items = spec.get("items", {})
        return tuple(_as_python(v, items) for v in value)
    types = spec.get("type")
    types = types if isinstance(types, list) else [types]
    if "number" in types and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def setting(key: str, **field_args: Any) -> Any:
    """A dataclass field for config key `key`, with the schema's default (none if the schema
    states none: then the field is required). `field_args`: other `dataclasses.field`
    arguments (not ``default``: the schema states it; a ``default_factory`` builds a nested
    settings object whose own fields read their defaults)."""
    node = schema_node(key)
    if "default" in node and "default_factory" not in field_args:
        default = _as_python(node["default"], node)
        if isinstance(default, Mapping):
            field_args["default_factory"] = lambda: dict(default)
        else:
            field_args["default"] = default
    return dataclasses.field(metadata={_KEY: key}, **field_args)


def schema_type(spec: Mapping[str, Any]) -> Any:
    """The Python type of a value of schema `spec`: an enum or const a Literal, integer int,
    number float, string str, boolean bool, an object a mapping, an array a tuple of its items'
    type, a list of types or ``anyOf`` their union (null: None)."""
    spec = _resolved(spec)
    if "enum" in spec:
        return Literal[tuple(spec["enum"])]
    if "const" in spec:
        return Literal[spec["const"]]
    if "anyOf" in spec:
        return functools.reduce(operator.or_, [schema_type(s) for s in spec["anyOf"]])
    types = spec.get("type")
    if isinstance(types, list):
        return functools.reduce(operator.or_, [schema_type({**spec, "type": t}) for t in types])
    if types == "array":
        return tuple[schema_type(spec.get("items", {})), ...]
    simple = {"integer": int, "number": float, "string": str, "boolean": bool}
    if types == "object":
        return Mapping[str, Any]
    return type(None) if types == "null" else simple.get(types, Any)


def schema_fields(
    section: str, *, skip: Iterable[str] = (), names: Mapping[str, str] | None = None
) -> Callable[[C], C]:
    """Class decorator (under ``@dataclass``): a field per key of config section `section`
    (but `skip`, keys other code reads), after the class's own fields, in the schema's order
    (those without a default first), typed by `schema_type`, with `setting`'s default and
    key. `names`: config key -> field name where the two differ. So a settings object's
    fields, types, defaults and bounds are written once, in the schema; the class keeps what
    the schema cannot say."""
    skip = set(skip)
    names = dict(names or {})

    def add_fields(cls: C) -> C:
        annotations = dict(cls.__dict__.get("__annotations__", {}))
        keys = [k for k in _resolved(schema_node(section))["properties"] if k not in skip]
        # the keys without a default first: a dataclass field without one cannot follow one with
        keys.sort(key=lambda k: "default" in schema_node(f"{section}.{k}"))
        for key in keys:
            spec = schema_node(f"{section}.{key}")
            name = names.get(key, key)
            if name in annotations:
                raise TypeError(f"{cls.__name__}.{name}: declared in the class and the schema")
            annotations[name] = schema_type(spec)
            setattr(cls, name, setting(f"{section}.{key}"))
        cls.__annotations__ = annotations
        cls.schema_section = section
        cls.schema_skip = tuple(sorted(skip))  # what `io.config.settings_from` leaves alone
        return cls

    return add_fields


class SchemaSettings:
    """Base of a settings dataclass whose fields are a config section's keys (`schema_fields`
    names the section): `from_config` reads the section (`io.config.settings_from`; the keys
    `schema_fields` skipped are left to the rules), and every object, however built (`tiny()`,
    `replace`), is held to the schema's bounds (`check_settings`). A class adds only what the
    schema cannot say: rules between keys (in its own ``__post_init__``, after this one's),
    budgets for tests, derived values."""

    schema_section: ClassVar[str] = ""
    schema_skip: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_config(cls, section: Mapping[str, Any] | None) -> Self:
        """Settings from the class's config section (`schema_section`)."""
        return settings_from(cls, section, where=cls.schema_section)


def _resolved(node: Mapping[str, Any]) -> Mapping[str, Any]:
    """`node`, or the definition its ``$ref`` names."""
    if "$ref" in node:
        return config_schema()["$defs"][node["$ref"].split("/")[-1]]
    return node


def not_config(default: Any = dataclasses.MISSING, **field_args: Any) -> Any:
    """A dataclass field that is not a config key (a value the caller gives, or a constant of
    the method): the schema-vs-settings test exempts it."""
    return dataclasses.field(default=default, metadata={_KEY: None}, **field_args)


def config_key(f: dataclasses.Field) -> str | None:
    """The config key of a settings field (`setting`), None for `not_config`; KeyError for a
    field declared with neither."""
    if _KEY not in f.metadata:
        raise KeyError(f"field {f.name!r} is not from the schema and not marked not_config()")
    return f.metadata[_KEY]


def check_settings(obj: Any) -> None:
    """Hold every config-key field of settings dataclass `obj` to its schema (type, bounds).

    Raises ValueError naming the key, e.g. ``align.epochs must be an integer >= 1, got 0``.
    A field holding a nested settings object (a dataclass) is left to that object's check.
    """
    for f in dataclasses.fields(obj):
        key = f.metadata.get(_KEY)
        if key is None:
            continue
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):  # a nested settings object checks itself
            continue
        problem = _violation(value, schema_node(key))
        if problem is not None:
            where, what, value = problem
            raise ValueError(f"{key}{where} must be {what}, got {value!r}")


# --------------------------------------------------------------------------- the checker


def _is_type(value: Any, name: str) -> bool:
    if name == "null":
        return value is None
    if name == "boolean":
        return isinstance(value, bool)
    if name == "string":
        return isinstance(value, str)
    if name == "array":
        return isinstance(value, list | tuple)
    if name == "object":
        return isinstance(value, Mapping)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    if not math.isfinite(value):
        return False
    return name == "number" or float(value).is_integer()


_TYPE_WORDS = {
    "integer": "an integer",
    "number": "a finite number",
    "string": "a text",
    "boolean": "true or false",
    "array": "a list",
    "null": "null",
    "object": "a mapping",
}

_BOUND_WORDS = {
    "minimum": ">=",
    "maximum": "<=",
    "exclusiveMinimum": ">",
    "exclusiveMaximum": "<",
}


def describe(spec: Mapping[str, Any]) -> str:
    """What `spec` asks of a value, in words: ``an integer >= 1``, ``one of 'vit', 'pixel'``."""
    if "anyOf" in spec:
        return " or ".join(describe(s) for s in spec["anyOf"])
    if "enum" in spec:
        return "one of " + ", ".join(repr(v) for v in spec["enum"])
    if "const" in spec:
        return repr(spec["const"])
    types = spec.get("type", [])
    types = types if isinstance(types, list) else [types]
    words = " or ".join(_TYPE_WORDS[t] for t in types) or "a value"
    bounds = [" and ".join(f"{_BOUND_WORDS[k]} {spec[k]}" for k in _BOUND_WORDS if k in spec)]
    bounds = [b for b in bounds if b]
    if "multipleOf" in spec:
        bounds.append(f"a multiple of {spec['multipleOf']}")
    if "minItems" in spec or "maxItems" in spec:
        lo, hi = spec.get("minItems", 0), spec.get("maxItems")
        bounds.append(f"of {lo} items" if lo == hi else f"of at least {lo} items")
        if hi is not None and hi != lo:
            bounds[-1] += f" and at most {hi}"
    if spec.get("uniqueItems"):
        bounds.append("without repeats")
    if "minLength" in spec:
        bounds.append(f"of at least {spec['minLength']} characters")
    if "contains" in spec:
        bounds.append(f"containing {describe(spec['contains'])}")
    if "items" in spec:
        bounds.append(f"of {describe(spec['items'])}")
    return " ".join([words, *bounds]) if bounds else words


def _violation(value: Any, spec: Mapping[str, Any], where: str = "") -> tuple | None:
    """(where, what is asked, the value) of the first way `value` breaks `spec`, or None."""
    unknown = set(spec) - _ANNOTATIONS - _KNOWN
    if unknown:
        raise NotImplementedError(f"schema keywords {sorted(unknown)} are not checked here")
    bad = (where, describe(spec), value)
    if "anyOf" in spec:
        return None if any(_violation(value, s) is None for s in spec["anyOf"]) else bad
    if "enum" in spec and value not in spec["enum"]:
        return bad
    if "const" in spec and value != spec["const"]:
        return bad
    types = spec.get("type")
    if types is not None:
        types = types if isinstance(types, list) else [types]
        if not any(_is_type(value, t) for t in types):
            return bad
    if isinstance(value, int | float) and not isinstance(value, bool):
        if not math.isfinite(value):
            return bad
        for key, holds in (
            ("minimum", lambda v, b: v >= b),
            ("maximum", lambda v, b: v <= b),
            ("exclusiveMinimum", lambda v, b: v > b),
            ("exclusiveMaximum", lambda v, b: v < b),
            ("multipleOf", lambda v, b: v % b == 0),
        ):
            if key in spec and not holds(value, spec[key]):
                return bad
    if isinstance(value, str) and len(value) < spec.get("minLength", 0):
        return bad
    if isinstance(value, list | tuple):
        if not spec.get("minItems", 0) <= len(value) <= spec.get("maxItems", len(value)):
            return bad
        if spec.get("uniqueItems") and len(set(value)) != len(value):
            return bad
        if "contains" in spec and all(_violation(v, spec["contains"]) for v in value):
            return bad
        if "items" in spec:
            for i, v in enumerate(value):
                inner = _violation(v, spec["items"], f"{where}[{i}]")
                if inner is not None:
                    return inner
    if isinstance(value, Mapping):
        if len(value) < spec.get("minProperties", 0):
            return bad
        missing = [k for k in spec.get("required", ()) if k not in value]
        if missing:
            return (f"{where}.{missing[0]}", "given", None)
        for k, v in value.items():
            if k in spec.get("properties", {}):
                inner = _violation(v, spec["properties"][k], f"{where}.{k}")
                if inner is not None:
                    return inner
                continue
            if spec.get("additionalProperties") is False:
                return (f"{where}.{k}", "a known key", k)
            if "propertyNames" in spec and _violation(k, spec["propertyNames"]) is not None:
                return (f"{where}.{k}", f"a key {describe(spec['propertyNames'])}", k)
            if isinstance(spec.get("additionalProperties"), Mapping):
                inner = _violation(v, spec["additionalProperties"], f"{where}.{k}")
                if inner is not None:
                    return inner
    return None


_KNOWN = frozenset(
    {"type", "enum", "const", "anyOf", "items", "contains", "minLength", "uniqueItems"}
    | {"propertyNames", "additionalProperties", "properties", "required", "minProperties"}
    | {"minItems", "maxItems", "multipleOf", *_BOUND_WORDS}
)
