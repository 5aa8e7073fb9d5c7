"""The schema is the one statement of each setting: every settings field is a schema key with
the schema's default and is held to the schema's bounds, no more and no less."""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib
import json
import math
import re
from pathlib import Path

import pytest
import yaml
from snakemake_run import ROOT, validated

from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.corpus.sim.samples import CorpusSettings
from tacgen_lib.corpus.splits import SplitSettings
from tacgen_lib.features.families import BackboneSpec, FamilySettings
from tacgen_lib.features.settings import (
    DinoSettings,
    FeatureSettings,
    MaeSettings,
    PretrainedVsRandomSettings,
    SimclrSettings,
)
from tacgen_lib.generate.pixel.settings import Pix2PixSettings, PixelDDPMSettings, PixelSettings
from tacgen_lib.generate.regime_sets import RegimeSettings
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.visibility import VisibilitySettings
from tacgen_lib.io import schema
from tacgen_lib.io.config import load_schema, schema_copy
from tacgen_lib.io.schema import check_settings, config_key, schema_node
from tacgen_lib.policy.settings import PolicySettings
from tacgen_lib.probes.settings import MLPGrid, ProbeFamily, ProbeSettings, RobustnessSettings
from tacgen_lib.probes.transfer import TransferSettings

#: every settings class, and how the default config builds one (the base each bound is tried on)
BUILDERS = {
    SplitSettings: lambda c: SplitSettings.from_config(c["splits"]),
    AlignSettings: lambda c: AlignSettings.from_config(c["align"]),
    BackboneSpec: lambda c: BackboneSpec.from_config(c["features"]["backbones"]["vision"]),
    FeatureSettings: lambda c: FeatureSettings.from_config(c["features"]),
    DinoSettings: lambda c: DinoSettings.from_config(c["features"]["pretrain"]),
    MaeSettings: lambda c: MaeSettings.from_config(c["features"]["mae"]),
    SimclrSettings: lambda c: SimclrSettings.from_config(c["features"].get("simclr")),
    PretrainedVsRandomSettings: lambda c: PretrainedVsRandomSettings.from_config(
        c["features"]["pretrained_vs_random"]
    ),
    VisibilitySettings: lambda c: VisibilitySettings.from_config(c["features"]["visibility"]),
    GenerateSettings: lambda c: GenerateSettings.from_config(c["generate"]),
    RegimeSettings: lambda c: RegimeSettings.from_config(c["regime"]),
    PixelSettings: lambda c: PixelSettings.from_config(c["pixel"]),
    Pix2PixSettings: lambda c: Pix2PixSettings.from_config(c["pixel"]["pix2pix"]),
    PixelDDPMSettings: lambda c: PixelDDPMSettings.from_config(c["pixel"]["ddpm"]),
    PolicySettings: lambda c: PolicySettings.from_config(c["policy"]),
    ProbeFamily: lambda c: ProbeFamily.from_config("mass", c["probes"]["families"]["mass"]),
    MLPGrid: lambda c: MLPGrid.from_config(c["probes"]["robustness"]["mlp"]),
    RobustnessSettings: lambda c: RobustnessSettings.from_config(c["probes"]["robustness"]),
    ProbeSettings: lambda c: ProbeSettings.from_config(c["probes"], "ridge", 0),
    TransferSettings: lambda c: TransferSettings.from_config(c["transfer"]),
    FamilySettings: lambda c: FamilySettings.from_config(c),
    # the regime's natural corpus: every key of the definition, rho among them, applies to it
    CorpusSettings: lambda c: CorpusSettings.from_config({**c["regime"]["corpus"], "name": "p"}),
}


FIELDS = [(cls, f) for cls in BUILDERS for f in dataclasses.fields(cls)]


def _ids(case) -> str:
    cls, f = case
    return f"{cls.__name__}.{f.name}"


def test_every_settings_class_is_checked_here():
    """A class that reads a config section (`settings_from`, `SchemaSettings`) is in BUILDERS"""
    found = set()
    for path in (ROOT / "tacgen_lib").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and any(
                isinstance(n, ast.Name) and n.id in ("settings_from", "SchemaSettings")
                for n in ast.walk(node)
            ):
                found.add((node.name, str(path.relative_to(ROOT))))
    named = {c.__name__ for c in BUILDERS} | {"SchemaSettings"}  # the base
    assert {name for name, _ in found} <= named, sorted(found)


@pytest.mark.parametrize("case", FIELDS, ids=_ids)
def test_field_is_a_schema_key_with_the_schema_default(case):
    cls, f = case
    key = config_key(f)  # KeyError: declared with neither setting() nor not_config()
    if key is None:
        return
    node = schema_node(key)
    default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
    if "default" not in node:
        assert default is dataclasses.MISSING, f"{key}: the schema states no default"
        return
    if dataclasses.is_dataclass(default):  # a nested settings object: its own fields check
        assert node["default"] == {}, key
        return
    want = node["default"]
    got = list(default) if isinstance(default, tuple) else default
    assert got == want and type(got) is not bool or got is want, (key, got, want)


def _bad_values(node: dict) -> list:
    """Values that break one bound of `node` each."""
    out = []
    if "enum" in node:
        out.append("not-an-option")
    if "minimum" in node:
        out.append(node["minimum"] - 1)
    if "exclusiveMinimum" in node:
        out.append(node["exclusiveMinimum"])
    if "maximum" in node:
        out.append(node["maximum"] + 1)
    if "exclusiveMaximum" in node:
        out.append(node["exclusiveMaximum"])
    if node.get("type") == "integer":
        out.append(2.5)
    items = node.get("items")
    if node.get("type") == "array" and isinstance(items, dict):
        if node.get("minItems", 0) >= 1:
            out.append(())
        for bad in _bad_values(items):
            out.append((bad,) * max(1, node.get("minItems", 1)))
    return out


def _edge_values(node: dict) -> list:
    """Values on the schema's inclusive bounds (what the settings must accept)."""
    return [node[k] for k in ("minimum", "maximum") if k in node and "enum" not in node]


@pytest.fixture(scope="module")
def bases():
    cfg = validated("test.yaml")
    return {cls: build(cfg) for cls, build in BUILDERS.items()}


#: a schema definition read where the user names the declaration -> that place in BUILDERS' base
#: objects (CorpusSettings' base is corpus "p")
WRITTEN_AS = {"$defs.simulated_corpus": "corpora.p"}


def _as_written(key: str) -> str:
    """The config key as an error names it: a definition's key at its place in the config."""
    for definition, place in WRITTEN_AS.items():
        if key.startswith(f"{definition}."):
            return place + key[len(definition) :]
    return key


@pytest.mark.parametrize("case", FIELDS, ids=_ids)
def test_field_is_held_to_the_schema_bounds(case, bases):
    """Each value that breaks a bound of the schema is refused, naming the key; each value on
    an inclusive bound is accepted (a hand-written bound that differs fails here)."""
    cls, f = case
    key = config_key(f)
    if key is None or dataclasses.is_dataclass(getattr(bases[cls], f.name)):
        return
    node = schema_node(key)
    key = _as_written(key)
    for bad in _bad_values(node):
        with pytest.raises(ValueError, match=re.escape(key)):
            dataclasses.replace(bases[cls], **{f.name: bad})
    for edge in _edge_values(node):
        value = float(edge) if node.get("type") == "number" else edge
        try:
            dataclasses.replace(bases[cls], **{f.name: value})
        except ValueError as exc:
            assert key not in str(exc) or "need" in str(exc), (key, value, exc)


def test_the_checker_refuses_non_finite_numbers_and_names_list_items():
    base = AlignSettings.tiny()
    with pytest.raises(ValueError, match=r"align\.lr must be a finite number > 0, got inf"):
        dataclasses.replace(base, lr=math.inf)
    grid = MLPGrid()
    with pytest.raises(ValueError, match=r"probes\.robustness\.mlp\.widths\[1\] must be"):
        dataclasses.replace(grid, widths=(8, 0))
    check_settings(grid)


def test_settings_modules_state_no_default_but_the_schemas():
    """No settings field of these modules carries a literal default beside its `setting`."""
    for cls in BUILDERS:
        module = importlib.import_module(cls.__module__)
        source = Path(module.__file__).read_text()
        tree = ast.parse(source)
        node = next(
            n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == cls.__name__
        )
        for stmt in node.body:
            if isinstance(stmt, ast.AnnAssign) and stmt.value is not None:
                call = stmt.value
                assert isinstance(call, ast.Call) and getattr(call.func, "id", "") in (
                    "setting",
                    "not_config",
                ), f"{cls.__name__}.{ast.unparse(stmt.target)}"


def test_the_schema_is_read_from_its_json_copy_only_where_the_copy_is_current(tmp_path):
    path = tmp_path / "schema.yaml"
    path.write_text("a: 1\n")
    assert load_schema(path) == {"a": 1}  # no copy
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    schema_copy(path).write_text(json.dumps({"source_sha256": digest, "schema": {"a": 2}}))
    assert load_schema(path) == {"a": 2}  # the copy of these bytes
    path.write_text("a: 3\n")
    assert load_schema(path) == {"a": 3}  # a stale copy is passed over


def test_the_shipped_json_copy_is_current_and_equals_the_yaml():
    """The copy jobs read is the YAML's own content (a key or value JSON cannot hold as YAML
    does, such as a number as a mapping key, would differ here) written from its current bytes
    (tools/config_reference.py writes it)."""
    path = ROOT / "config" / "config.schema.yaml"
    copy_ = json.loads(schema_copy(path).read_text())
    assert copy_["source_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest(), (
        "config/config.schema.json is stale: run tools/config_reference.py"
    )
    assert copy_["schema"] == yaml.safe_load(path.read_text())


def _as_json(value):
    """A settings value as the JSON document jsonschema validates (tuples are arrays)."""
    if isinstance(value, tuple | list):
        return [_as_json(v) for v in value]
    return value


@pytest.mark.parametrize("case", FIELDS, ids=_ids)
def test_the_settings_checker_agrees_with_jsonschema(case):
    """io.schema checks a settings value without importing jsonschema (which a job would pay
    for at every start); on every settings key it must judge each value as jsonschema does:
    the key's default, the values on and past its bounds, and values of the wrong type."""
    from jsonschema import Draft202012Validator

    cls, f = case
    key = config_key(f)
    if key is None:
        return
    node = schema_node(key)
    if "$ref" in node:  # a nested settings object: its own fields are cases of their own
        return
    validator = Draft202012Validator(node)
    values = [*_bad_values(node), *_edge_values(node), "x", None, True, 2.5, -1, (), ("x",)]
    if "default" in node:
        values.append(node["default"])
    for value in values:
        ours = schema._violation(value, node) is None
        assert ours == validator.is_valid(_as_json(value)), (key, value, ours)


def test_a_declaration_read_at_several_places_names_the_place_read():
    """One schema for every backbone declaration (and every probe family): a bound broken in
    one of them names that declaration's key, not the schema section's."""
    bad = {"arch": "vit_tiny", "num_register_tokens": -1}
    for where in ("features.backbones.tactile", "backbones.families.mae.vision"):
        with pytest.raises(ValueError, match=rf"^{re.escape(where)}\.num_register_tokens must"):
            BackboneSpec.from_config(bad, where)
    family = {**validated("test.yaml")["probes"]["families"]["mass"], "kind": "lasso"}
    with pytest.raises(ValueError, match=r"^probes\.families\.mass\.kind must be one of"):
        ProbeFamily.from_config("mass", family)
