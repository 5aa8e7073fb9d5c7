"""Helpers of the probes stage (family specs, input lists, report items); included by probes.smk."""

from tacgen_lib.probes.protocol_variants import PROTOCOLS
from tacgen_lib.probes.settings import (
    RobustnessSettings,
    check_families,
    has_aligned_rows,
)

PROBES = config["probes"]
check_families(PROBES["families"])  # no family repeats another's rows
PROBE_FAMILIES = sorted(PROBES["families"])
# probe robustness: every family under raw, the robustness families under each
# other protocol variant (not where it equals raw); (family, protocol) pairs
ROBUST = RobustnessSettings.from_config(PROBES["robustness"], PROBES["families"])
PROBE_JOBS = ROBUST.jobs(PROBES["families"])
PROBE_DIR = "results/probes/{family}/protocol~{protocol}"
PROBE_REPORT = "results/report/probes"
PROBE_TABLES = [
    "controlled",
    "paired",
    "sweep",
    "align_seeds",
    "variants",
    "controls",
    "fusions",
]
PROBE_FIGURES = ["forest", "confusion"]
ROBUSTNESS_TABLES = ["robustness", "multiplicity", "within_scale", "training_size"]
PROBE_EDGES = ["seed~{seed}", "sweep~{seed}", "confusion~{seed}"]


def probe_job_edges(edge):
    """`edge` ("seed~{seed}", ...) of every probe job: (family, protocol) x probe seed."""
    return [
        f"{PROBE_DIR}/{edge}.parquet".format(family=f, protocol=p, seed=s)
        for f, p in PROBE_JOBS
        for s in PROBES["seeds"]
    ]


def probe_family(family):
    return {"name": family, **PROBES["families"][family]}


def probe_align_seeds(family):
    """Alignment seeds whose aligned projections a family probes (none for pixel-V families)."""
    fam = probe_family(family)
    return config["align"]["seeds"] if has_aligned_rows(fam["vision"]) else []


def probe_inputs(wildcards):
    """Edges one probe family reads: labels, splits, raw V/T features, aligned projections."""
    fam = probe_family(wildcards.family)
    heads = PROBES["heads"]
    return {
        "manifest": "results/corpus/manifest.parquet",
        "splits": "results/corpus/splits.parquet",
        "vision": feature_edge(fam["corpus"], "vision"),
        "tactile": [
            feature_edge(fam["corpus"], "tactile", v)
            for v in config["preprocess"]["variants"]
        ],
        "aligned": [
            aligned_edge(
                fam["heads_from"],
                fam["corpus"],
                heads["variant"],
                seed,
                heads["tau"],
                heads["n_train"],
            )
            for seed in probe_align_seeds(wildcards.family)
        ],
    }


def probe_raw_inputs(wildcards):
    """`probe_inputs` without the aligned projections (the raw-feature robustness rules)."""
    return {k: v for k, v in probe_inputs(wildcards).items() if k != "aligned"}


def probe_report_dir(name, label):
    """A directory of figures, one per probe family, each its own report item."""
    return report(
        directory(f"{PROBE_REPORT}/{name}"),
        patterns=["{family}.png"],
        caption=f"../workflow/report/probe_{name}.rst",
        category=category("Probes"),
        subcategory=label,
        labels={"family": "{family}"},
    )


def probe_report_item(name, ext, caption, label, page="Probes"):
    return report(
        f"{PROBE_REPORT}/{name}.{ext}",
        caption=f"../workflow/report/probe_{caption}.rst",
        category=category(page),
        subcategory="Figures" if ext == "png" else "Tables",
        labels={"item": label},
    )
