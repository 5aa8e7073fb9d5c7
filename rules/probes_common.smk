"""Helpers of the probes stage (family specs, input lists, report items); included by probes.smk."""

from tacgen_lib.probes.protocol import check_families, has_aligned_rows

PROBES = config["probes"]
check_families(PROBES["families"])  # no family repeats another's rows
PROBE_FAMILIES = sorted(PROBES["families"])
PROBE_DIR = "results/probes/{family}"
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
PROBE_EDGES = ["seed~{seed}", "sweep~{seed}", "confusion~{seed}"]


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


def probe_report_item(name, ext, caption, label):
    return report(
        f"{PROBE_REPORT}/{name}.{ext}",
        caption=f"../workflow/report/probe_{caption}.rst",
        category="Probes",
        subcategory="Figures" if ext == "png" else "Tables",
        labels={"item": label},
    )
