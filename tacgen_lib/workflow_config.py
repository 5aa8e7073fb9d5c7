"""The workflow's configuration checked as the Snakefile reads it (rules/common.smk).

`validate_config` runs the schema's validation and defaults (`io.config.validate_schema`, the
ground floor), then the cross-references a schema cannot see: the corpus key rules
(`corpus.keys.corpus_key_errors`), scenes, and the keys that name a corpus, variant or heads
cell. Errors name the key as a dotted path and the file, so a bad value stops the run before
any job starts with a message that says what to fix.
"""

from __future__ import annotations

from pathlib import Path

from tacgen_lib.corpus.keys import corpus_key_errors
from tacgen_lib.features.settings import pretraining_corpora
from tacgen_lib.generate.regime_sets import NATURAL_PREFIX, regime_corpora
from tacgen_lib.io.config import ConfigError, load_yaml, validate_schema

__all__ = ["ConfigError", "validate_config"]


def _well_formed(regime: object) -> bool:
    """Whether config regime is a mapping whose corpus and rhos the regime's corpora can be
    made from (`regime_sets.regime_corpora`); anything else is the schema's to refuse."""
    if regime is None:
        return True
    if not isinstance(regime, dict):
        return False
    # read before the schema fills or checks anything: a missing key is the schema's to name
    rhos, corpus = regime.get("rhos"), regime.get("corpus")
    return (
        (rhos is None or isinstance(rhos, list))
        and all(isinstance(r, (int, float)) and not isinstance(r, bool) for r in rhos or ())
        and (corpus is None or isinstance(corpus, dict))
    )


def validate_config(config: dict, schema_path: str | Path, *, source: str = "config") -> dict:
    """Validate `config` in place (`io.config.validate_schema`: schema and defaults), then
    check its cross-references; raises ConfigError naming the key. Returns `config`.

    The regime's natural corpora, one per rho of config regime (`regime_sets.regime_corpora`),
    join config corpora first, so that each is checked like any declared corpus and other keys
    (features.pretrain.corpus) may name them; a declared corpus of one of their names that is
    not the regime's own is refused."""
    joined = _join_regime_corpora(config, source)
    validate_schema(config, schema_path, source=source)
    _check_simulated_corpora(config, joined, source)
    _check_corpus_references(config, source)
    _check_variants_and_heads(config, source)
    fr = config["splits"]["fractions"]
    if abs(sum(fr.values()) - 1.0) > 1e-9:
        raise ConfigError(f"{source}: splits.fractions: must sum to 1, got {sum(fr.values()):g}")
    return config


def _join_regime_corpora(config: dict, source: str) -> dict:
    """Add the regime's natural corpora to config corpora (`validate_config`); returns them."""
    regime, corpora = config.get("regime"), config.setdefault("corpora", {})
    # a malformed regime or corpora is left to the schema, which names the key
    joined = {}
    if _well_formed(regime) and isinstance(corpora, dict):
        try:
            joined = regime_corpora(regime)
        except ValueError as err:  # names its key (regime.corpus, regime.rhos)
            raise ConfigError(f"{source}: {err}") from err
    for name, decl in joined.items():
        have = corpora.get(name)
        if have is not None and have != decl:
            raise ConfigError(
                f"{source}: corpora.{name}: the name belongs to the regime's corpus at rho = "
                f"{decl['rho']:g} (config regime.corpus, regime.rhos); rename your corpus"
            )
        config["corpora"][name] = decl
    return joined


def _check_simulated_corpora(config: dict, joined: dict, source: str) -> None:
    """Every simulated corpus's keys, and its scene in the scenes file."""
    scenes_file = Path(config["scenes_file"])
    scenes = load_yaml(scenes_file) if scenes_file.exists() else None

    def written_at(name: str, key: str) -> str:
        """Where the user wrote corpus `name`'s `key`: a regime corpus's under regime.corpus."""
        return f"regime.corpus.{key} (corpus {name})" if name in joined else f"corpora.{name}.{key}"

    for name, corpus in config["corpora"].items():
        if corpus["kind"] == "simulated":
            for key, message in corpus_key_errors(corpus):
                raise ConfigError(f"{source}: {written_at(name, key)}: {message}")
            if scenes is None:
                raise ConfigError(f"{source}: scenes_file: {scenes_file} does not exist")
            if corpus["scene"] not in scenes:
                raise ConfigError(
                    f"{source}: {written_at(name, 'scene')}: unknown scene {corpus['scene']!r} "
                    f"(scenes in {scenes_file}: {', '.join(sorted(scenes))})"
                )


def _unknown_corpus(config: dict, source: str, key: str, name: str) -> ConfigError:
    """The error for `key` naming undeclared corpus `name`; where `name` is a regime corpus's,
    it adds the rhos the regime declares: such a corpus exists only at a rho of regime.rhos
    (switching the regime off, rhos [], leaves none for features.pretrain.corpus to name)."""
    known = ", ".join(sorted(config["corpora"]))
    message = f"{source}: {key}: unknown corpus {name!r} (corpora: {known})"
    if str(name).startswith(NATURAL_PREFIX):
        rhos = (config.get("regime") or {}).get("rhos")
        message += (
            f"; {name!r} is the name of the regime's natural corpus at a rho, which exists only "
            f"where regime.rhos names that rho (regime.rhos: {rhos!r})"
        )
    return ConfigError(message)


def _check_corpus_references(config: dict, source: str) -> None:
    """Every key that names a corpus names a declared one; every probe family's heads come
    from a corpus the alignment trains on."""
    for name in config["splits"]["by_scale"]:
        if name not in config["corpora"]:
            raise _unknown_corpus(config, source, f"splits.by_scale.{name}", name)
    corpora = set(config["corpora"])
    refs = [
        (f"features.pretrain.corpus[{i}]", c)
        for i, c in enumerate(pretraining_corpora(config["features"]["pretrain"]))
    ]
    refs += [
        (
            "features.pretrained_vs_random.corpus",
            config["features"]["pretrained_vs_random"]["corpus"],
        ),
    ]
    refs += [(f"align.corpora[{i}]", c) for i, c in enumerate(config["align"]["corpora"])]
    for fam, spec in config["probes"]["families"].items():
        refs += [
            (f"probes.families.{fam}.corpus", spec["corpus"]),
            (f"probes.families.{fam}.heads_from", spec["heads_from"]),
        ]
    for key, name in refs:
        if name not in corpora:
            raise _unknown_corpus(config, source, key, name)
    for fam, spec in config["probes"]["families"].items():
        if spec["heads_from"] not in config["align"]["corpora"]:
            raise ConfigError(
                f"{source}: probes.families.{fam}.heads_from: {spec['heads_from']!r} is not in align.corpora, "
                "so no heads are trained on it"
            )


def _check_variants_and_heads(config: dict, source: str) -> None:
    """Every key that names a tactile variant names a preprocessed one; the probes' heads are
    a cell the alignment grid trains."""
    variants = set(config["preprocess"]["variants"])
    vrefs = [
        ("features.pretrain.variant", config["features"]["pretrain"]["variant"]),
        ("probes.heads.variant", config["probes"]["heads"]["variant"]),
    ]
    vrefs += [(f"align.variants[{i}]", v) for i, v in enumerate(config["align"]["variants"])]
    for key, name in vrefs:
        if name not in variants:
            raise ConfigError(f"{source}: {key}: variant {name!r} is not in preprocess.variants")
    heads = config["probes"]["heads"]
    if heads["variant"] not in config["align"]["variants"]:
        raise ConfigError(
            f"{source}: probes.heads.variant: {heads['variant']!r} is not in align.variants"
        )
    if heads["tau"] not in config["align"]["taus"]:
        raise ConfigError(f"{source}: probes.heads.tau: {heads['tau']} is not in align.taus")
    if heads["n_train"] not in config["align"]["n_train"]:
        raise ConfigError(
            f"{source}: probes.heads.n_train: {heads['n_train']} is not in align.n_train"
        )
