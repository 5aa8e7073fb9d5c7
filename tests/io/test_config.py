"""Config validation: a bad value stops the run with a message naming the key."""

from __future__ import annotations

import copy
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from tacgen_lib.workflow_config import ConfigError, validate_config

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = ROOT / "config" / "config.schema.yaml"


def _config(name: str = "config.yaml") -> dict:
    cfg = yaml.safe_load((ROOT / "config" / name).read_text())
    cfg["scenes_file"] = str(ROOT / cfg["scenes_file"])
    return cfg


def _merged(overlay: str) -> dict:
    from snakemake.utils import update_config

    cfg = _config()
    update_config(cfg, yaml.safe_load((ROOT / "config" / overlay).read_text()))
    return cfg


@pytest.mark.parametrize(
    "cfg",
    [_config(), _merged("test.yaml"), _merged("paper.yaml"), _merged("scaling.yaml")],
    ids=["default", "test", "paper", "scaling"],
)
def test_shipped_configs_are_valid(cfg):
    validate_config(cfg, SCHEMA)
    assert cfg["report"]["examples_per_corpus"] >= 1


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda c: c["align"].__setitem__("taus", [0.07, -0.1]),
            r"align\.taus\[1\]: -0\.1 is less than or equal to the minimum of 0",
        ),
        (
            lambda c: c["align"].__setitem__("taus", [0.0]),
            r"align\.taus\[0\]: 0\.0 is less than or equal",
        ),
        (lambda c: c["align"].__setitem__("seeds", []), r"align\.seeds: \[\] should be non-empty"),
        (
            lambda c: c["corpora"]["sim_paired"].__setitem__("kind", "mystery"),
            r"corpora\.sim_paired\.kind: 'mystery' is not one of",
        ),
        (
            lambda c: c["corpora"]["sim_paired"].__setitem__("n", -5),
            r"corpora\.sim_paired\.n: -5 is less than the minimum of 1",
        ),
        (
            lambda c: c["corpora"]["sim_paired"].__setitem__("n", "many"),
            r"corpora\.sim_paired\.n: 'many' is not of type 'integer'",
        ),
        (
            lambda c: c["corpora"]["sim_paired"].__setitem__("scene", "nowhere"),
            r"corpora\.sim_paired\.scene: unknown scene 'nowhere'",
        ),
        (
            lambda c: c["splits"]["by_scale"].__setitem__("ghost", {"train": [0.1], "test": [0.2]}),
            r"splits\.by_scale\.ghost: unknown corpus 'ghost'",
        ),
        (
            lambda c: c["splits"]["fractions"].__setitem__("test", 0.5),
            r"splits\.fractions: must sum to 1",
        ),
        (
            lambda c: c["features"]["pretrain"].__setitem__("corpus", ["sim_paired", "ghost"]),
            r"features\.pretrain\.corpus\[1\]: unknown corpus 'ghost'",
        ),
        (
            lambda c: c["corpora"].__setitem__("sim_natural_r0", c["corpora"]["sim_paired"]),
            r"corpora\.sim_natural_r0: the name belongs to the regime's corpus at rho = 0",
        ),
        (
            lambda c: c["features"]["pretrain"].__setitem__("corpus", []),
            r"features\.pretrain\.corpus: \[\] should be non-empty",
        ),
        (
            lambda c: c.__setitem__("algn", {}),
            r"\(top level\): Additional properties are not allowed \('algn' was unexpected\)",
        ),
    ],
)
def test_bad_values_name_the_key(edit, message):
    cfg = copy.deepcopy(_config())
    edit(cfg)
    with pytest.raises(ConfigError, match=message):
        validate_config(cfg, SCHEMA, source="config/config.yaml")


@pytest.mark.parametrize(
    "where, value",
    [
        (("align", "lr"), float("inf")),  # found by the fuzz test: `exclusiveMinimum: 0` lets it by
        (("align", "taus", 0), float("-inf")),
        (("features", "pretrain", "lr"), float("nan")),
    ],
)
def test_non_finite_numbers_are_refused_naming_the_key(where, value):
    cfg = _config()
    node = cfg
    for part in where[:-1]:
        node = node[part]
    node[where[-1]] = value
    with pytest.raises(ConfigError, match="is not a finite number") as err:
        validate_config(cfg, SCHEMA, source="bad.yaml")
    dotted = ".".join(str(p) for p in where[:-1]) + (
        f"[{where[-1]}]" if isinstance(where[-1], int) else f".{where[-1]}"
    )
    assert f"bad.yaml: invalid configuration\n  {dotted}: {value!r}" in str(err.value)


#: every YAML file the workflow reads: configs, scenes, the schema, the cluster profiles
YAML_FILES = sorted(
    p.relative_to(ROOT)
    for pattern in ("config/*.yaml", "config/**/*.yaml", "profiles/**/*.yaml")
    for p in ROOT.glob(pattern)
)


@pytest.mark.parametrize("path", YAML_FILES, ids=str)
def test_load_yaml_gives_what_the_pure_python_safe_loader_gives(path):
    from tacgen_lib.io.config import load_yaml

    want = yaml.load((ROOT / path).read_text(), Loader=yaml.SafeLoader)  # noqa: S506
    got = load_yaml(ROOT / path)
    assert got == want
    # the same types too (1 vs 1.0 vs "1"; == alone would let 1 == 1.0 by)
    assert repr(got) == repr(want)


def test_load_yaml_refuses_python_objects(tmp_path):
    from tacgen_lib.io.config import load_yaml

    bad = tmp_path / "bad.yaml"
    bad.write_text("x: !!python/object/apply:os.system ['true']\n")
    with pytest.raises(yaml.constructor.ConstructorError):
        load_yaml(bad)


def test_filled_defaults_are_copies_not_the_cached_schemas_own(tmp_path):
    """The schema is read once per process (`_schema`); a default list filled into one config
    and changed there must not change the default the next config gets."""
    first = _config()
    first["policy"].pop("size_range", None)
    validate_config(first, SCHEMA)
    default = copy.deepcopy(first["policy"]["size_range"])
    first["policy"]["size_range"][0] = 12345.0
    second = _config()
    second["policy"].pop("size_range", None)
    validate_config(second, SCHEMA)
    assert second["policy"]["size_range"] == default != first["policy"]["size_range"]


def test_an_edited_schema_is_read_again(tmp_path):
    schema = tmp_path / "schema.yaml"
    text = SCHEMA.read_text()
    schema.write_text(text)
    validate_config(_config(), schema)
    # a schema edit that refuses what passed: seen at once, not served from the cache
    schema.write_text(text.replace("required: [run_name,", "required: [no_such_key, run_name,"))
    with pytest.raises(ConfigError, match="no_such_key"):
        validate_config(_config(), schema)


def test_reading_settings_does_not_import_jsonschema():
    """Jobs read their settings (`settings_from`) and never validate: jsonschema (~0.1 s a
    job) is imported by validation only, at parse time."""
    code = textwrap.dedent(
        """
        import dataclasses, sys
        from tacgen_lib.io.config import settings_from

        @dataclasses.dataclass(frozen=True)
        class S:
            steps: int = 1

        assert settings_from(S, {"steps": 3}, where="x").steps == 3
        print("jsonschema" in sys.modules)
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stdout + out.stderr


@pytest.mark.parametrize(
    "change, key",
    [
        ({"n": 215}, "corpora.sim_transfer.n: n=215 is not a whole number of objects of 6"),
        ({"design": "controlled"}, "corpora.sim_transfer.contacts: key 'contacts' belongs to"),
        ({"rho": 0.5}, "corpora.sim_transfer.rho: key 'rho' belongs to design 'natural'"),
    ],
)
def test_a_corpus_breaking_a_cross_key_rule_stops_validation_naming_the_key(change, key):
    cfg = _config()
    cfg["corpora"]["sim_transfer"].update(change)
    with pytest.raises(ConfigError, match=re.escape(key)):
        validate_config(cfg, SCHEMA, source="x.yaml")
