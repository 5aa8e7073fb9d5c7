"""Backbone families: the config (tacgen_lib.features.families) and the paths the rules of
rules/backbones.smk read."""

from tacgen_lib.features.families import (
    FamilySettings,
    check_backbone,
    check_checkpoint_file,
)
from tacgen_lib.features.families import BackboneSpec as _Spec
from tacgen_lib.features.settings import backbone_image_size

for _m in MODALITIES:
    check_backbone(
        _Spec.from_config(FEAT["backbones"][_m], f"features.backbones.{_m}"),
        where=f"features.backbones.{_m}",
        dino_epochs=int(PRETRAIN["epochs"]),
        mae_epochs=int(FEAT["mae"]["epochs"]),
        features_pool=FEAT["pool"],
    )
    # an official checkpoint must be here before any job runs (relative to the working
    # directory, where results/ lives)
    check_checkpoint_file(
        _Spec.from_config(FEAT["backbones"][_m]), where=f"features.backbones.{_m}"
    )

FAMILIES = FamilySettings.from_config(config)
for _f in FAMILIES.run:
    for _m in MODALITIES:
        check_checkpoint_file(
            FAMILIES.families[_f][_m], where=f"backbones.families.{_f}.{_m}"
        )
OWN_FAMILIES = FAMILIES.own(FEAT)
FAMILY_VARIANT = PROBES["heads"]["variant"]  # the tactile frames the probes read
FAMILY_PROBE = "results/backbones/{family}/probes.parquet"
FAMILY_CORPORA = sorted({PROBES["families"][p]["corpus"] for p in FAMILIES.probes})
_PROBE_SEED = PROBES["seeds"][0]
MAIN_FAMILIES = [f for f in FAMILIES.run if f not in OWN_FAMILIES]  # at most one
#: the (probe family, protocol) jobs a family is judged on
FAMILY_JOBS = [(p, q) for p in FAMILIES.probes for q in FAMILIES.protocols]
# the main family's rows are the probes stage's own headline rows when it probes every
# (probe family, protocol) asked here (nothing is computed twice); else family_probe makes them
MAIN_FROM_PROBES = [
    f for f in MAIN_FAMILIES if all(j in PROBE_JOBS for j in FAMILY_JOBS)
]
COMPUTED_FAMILIES = [f for f in FAMILIES.run if f not in MAIN_FROM_PROBES]
#: whether the findings page has backbone rows: some family is not the main one
FAMILY_FINDINGS = bool(FAMILIES.probes) and bool(OWN_FAMILIES)

if FAMILIES.run and FAMILIES.probes:
    TARGETS += ["results/report/backbones/table.html"]
    EDGES += ["results/backbones/summary.parquet"]
    EDGES += [FAMILY_PROBE.format(family=f) for f in COMPUTED_FAMILIES]
    for _f in OWN_FAMILIES:
        EDGES += [f"results/features/families/{_f}/{m}.pt" for m in MODALITIES]
        EDGES += [
            f"results/features/families/{_f}/{c}/{m}.parquet"
            for c in FAMILY_CORPORA
            for m in MODALITIES
        ]


def family_spec(family, modality):
    return FAMILIES.families[family][modality]


def family_labels(family):
    """What the report says of a family's two backbones."""
    return {
        m: family_spec(family, m).label(int(PRETRAIN["epochs"])) for m in MODALITIES
    }


def family_features(family, corpus, modality):
    """A family's feature edge of a corpus (the main edge for the main family)."""
    if family not in OWN_FAMILIES:
        return feature_edge(corpus, modality, FAMILY_VARIANT)
    return f"results/features/families/{family}/{corpus}/{modality}.parquet"


def family_frames(modality):
    """The frames a family's backbone of `modality` is extracted on, per probe corpus."""
    if modality == "vision":
        return [corpus_edge(c) for c in FAMILY_CORPORA]
    return [f"results/preprocess/{c}/{FAMILY_VARIANT}.parquet" for c in FAMILY_CORPORA]
