"""One settings object per stage: built from the validated config, every field reachable."""

from __future__ import annotations

import dataclasses

import pytest
import yaml
from snakemake_run import ROOT, validated

from tacgen_lib.align.settings import AlignSettings
from tacgen_lib.corpus.sim.samples import CorpusSettings
from tacgen_lib.features.settings import DinoSettings
from tacgen_lib.generate.pixel.settings import Pix2PixSettings, PixelDDPMSettings
from tacgen_lib.io.config import ConfigError, settings_from

SCHEMA = ROOT / "config" / "config.schema.yaml"


def schema_keys(*path: str) -> set[str]:
    node = yaml.safe_load(SCHEMA.read_text())
    for key in path:
        node = node["properties"][key]
    return set(node["properties"])


@pytest.mark.parametrize("overlay", [None, "test.yaml", "paper.yaml"])
def test_every_config_builds_every_settings_object(overlay):
    cfg = validated(overlay)
    align = AlignSettings.from_config(cfg["align"])
    assert align.feature == cfg["align"]["features"] and align.epochs == cfg["align"]["epochs"]
    dino = DinoSettings.from_config(cfg["features"]["pretrain"])
    assert dino.epochs == cfg["features"]["pretrain"]["epochs"]
    for name, corpus in cfg["corpora"].items():
        if corpus["kind"] == "simulated":
            assert CorpusSettings.from_config({"name": name, **corpus}).n == corpus["n"]


def test_every_settings_field_is_a_config_key():
    """A field that changes results but cannot be set from config would be a hidden knob."""
    align = {f.name for f in dataclasses.fields(AlignSettings)} - {"feature"} | {"features"}
    assert align <= schema_keys("align")
    assert {f.name for f in dataclasses.fields(DinoSettings)} <= schema_keys("features", "pretrain")


def test_dino_defaults_filled_by_the_schema_equal_the_dataclass_defaults():
    filled = validated()["features"]["pretrain"]
    for f in dataclasses.fields(DinoSettings):
        if f.name != "epochs":  # set by config.yaml itself
            assert filled[f.name] == f.default, f.name


@pytest.mark.parametrize("overlay", [None, "test.yaml", "paper.yaml"])
def test_every_config_builds_the_pixel_generators_settings(overlay):
    cfg = validated(overlay)["pixel"]
    assert Pix2PixSettings.from_config(cfg["pix2pix"]).steps == cfg["pix2pix"]["steps"]
    assert PixelDDPMSettings.from_config(cfg["ddpm"]).channels == tuple(cfg["ddpm"]["channels"])


@pytest.mark.parametrize(
    ("cls", "key"), [(Pix2PixSettings, "pix2pix"), (PixelDDPMSettings, "ddpm")]
)
def test_pixel_settings_are_the_schema_keys_with_the_schema_defaults(cls, key):
    """Every field of the pixel generators' settings is a config key, and every schema default
    equals the dataclass default (an empty section gets the code's own settings)."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    node = yaml.safe_load(SCHEMA.read_text())["properties"]["pixel"]["properties"][key]
    assert set(fields) == set(node["properties"])
    for name, spec in node["properties"].items():
        default = fields[name].default
        want = list(default) if isinstance(default, tuple) else default
        assert spec["default"] == want, f"pixel.{key}.{name}"


def test_settings_refuse_bad_values_naming_the_key():
    with pytest.raises(ValueError, match="align.budget"):
        AlignSettings.tiny(budget="minutes")
    with pytest.raises(ValueError, match="align.batch_size"):
        AlignSettings.tiny(batch_size=1)
    section = validated()["align"]
    assert AlignSettings.from_config({k: v for k, v in section.items() if k != "lr"}).lr == 1e-4
    with pytest.raises(ValueError, match="align.learning_rate: unknown key"):
        AlignSettings.from_config({**section, "learning_rate": 1e-3})
    with pytest.raises(ValueError, match="corpora.tiny.colour: unknown key"):
        CorpusSettings.from_config({**dataclasses.asdict(CorpusSettings.tiny()), "colour": 1})
    with pytest.raises(ValueError, match="corpora.x.seed: missing"):
        CorpusSettings.from_config({"name": "x", "design": "paired", "n": 2, "scene": "s"})
    with pytest.raises(ValueError, match=r"corpora\.tiny\.design must be one of 'paired'"):
        CorpusSettings.tiny(design="mixed")


def test_tiny_settings_are_small_and_overridable():
    assert AlignSettings.tiny().steps <= 30 and AlignSettings.tiny(steps=5).steps == 5
    assert DinoSettings.tiny().epochs == 1 and DinoSettings.tiny().out_dim < 1024
    assert CorpusSettings.tiny().n <= 8 and CorpusSettings.tiny(null=True).null


# --------------------------------------------------------------------------- the settings reader


@dataclasses.dataclass(frozen=True)
class _Example:
    name: str
    n: int = 3
    rate: float = 0.5
    flag: bool = False
    sizes: tuple[int, ...] = (1, 2)
    pair: tuple[float, str] = (1.0, "a")
    n_train: tuple[int | str, ...] = (10, "all")
    limit: int | None = None


def test_settings_from_reads_coerces_and_keeps_defaults():
    got = settings_from(
        _Example,
        {
            "name": 7,
            "n": 4.0,
            "rate": 2,
            "sizes": [3, 4.0],
            "pair": [2, "b"],
            "n_train": [50, "all"],
            "limit": None,
            "grid": [1, 2],
        },
        where="example",
        ignore=("grid",),
    )  # the grid is a key the rules read
    assert got == _Example("7", 4, 2.0, False, (3, 4), (2.0, "b"), (50, "all"), None)
    assert type(got.n) is int and type(got.rate) is float and type(got.sizes[1]) is int
    assert settings_from(_Example, {"name": "x"}, where="e") == _Example("x")
    # what the caller knows is given, never read
    assert settings_from(_Example, {"name": "x"}, where="e", n=9).n == 9
    assert settings_from(_Example, {"nom": "x"}, where="e", rename={"name": "nom"}).name == "x"


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({}, r"example\.name: missing"),
        ({"name": "x", "colour": 1}, r"example\.colour: unknown key \(known: "),
        ({"name": "x", "n": 2.5}, r"example\.n: 2\.5 is not a whole number"),
        ({"name": "x", "n": True}, r"example\.n: True is not a number"),
        ({"name": "x", "rate": "fast"}, r"example\.rate: 'fast' is not a number"),
        ({"name": "x", "flag": 1}, r"example\.flag: 1 is not true or false"),
        ({"name": "x", "sizes": 3}, r"example\.sizes: 3 is not a list"),
        ({"name": "x", "sizes": [1, "two"]}, r"example\.sizes\[1\]: 'two' is not a number"),
        ({"name": "x", "pair": [1.0]}, r"example\.pair: \[1\.0\] needs 2 items"),
        ({"name": "x", "limit": "none"}, r"example\.limit: 'none' is not a number"),
    ],
)
def test_settings_from_refuses_naming_the_key(section, message):
    with pytest.raises(ConfigError, match=message):
        settings_from(_Example, section, where="example")
