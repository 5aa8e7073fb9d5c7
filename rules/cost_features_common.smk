"""Helpers of the cost sweeps of the simulation and features knobs (settings, paths, the plan
of each knob's points); included by cost_features.smk."""

from tacgen_lib.cost.knob_metrics import knob_metric_ids
from tacgen_lib.features.archs import ARCHS

register_cost_knobs("corpus", ["presses", "tactile_resolution"])
register_cost_knobs("features", ["image_size", "backbone_arch", "pretrain_epochs"])
# COST and COST_KNOB_CONFIG (the configured knobs) come from cost_common.smk
SIM_KNOBS = [k for k in ("presses", "tactile_resolution") if k in COST_KNOB_CONFIG]
FEATURE_KNOBS = [
    k
    for k in ("image_size", "backbone_arch", "pretrain_epochs")
    if k in COST_KNOB_CONFIG
]
SIM_SWEEP = COST.get("sim_sweep") or {"corpus": "sim_paired", "n": 400}
SIM_BASE = SIM_SWEEP["corpus"]
SIM_DIR = "results/cost/sim/presses~{presses}/tactile~{tactile}/"
FEAT_DIR = "results/cost/features/size~{size}/arch~{arch}/epochs~{epochs}/"
PVR = config["features"]["pretrained_vs_random"]
PROBE_VARIANT = config["probes"]["heads"]["variant"]
if SIM_KNOBS and (
    SIM_BASE not in SIM_CORPORA or int(SIM_SWEEP["n"]) > int(CORPORA[SIM_BASE]["n"])
):
    raise ValueError(
        f"config cost.sim_sweep: corpus {SIM_BASE!r} must be a simulated corpus of the config "
        f"with n >= {SIM_SWEEP['n']} (its sample_ids and splits are reused)"
    )


def _hw(value):
    """A tactile resolution as the path writes it: [120, 160] -> '120x160'."""
    h, w = (int(v) for v in value)
    return f"{h}x{w}"


def sim_default():
    c = CORPORA.get(SIM_BASE, {})
    return {
        "presses": int(c.get("presses", 8)),
        "tactile": _hw(c.get("tactile_size", [120, 160])),
    }


def features_default():
    b = FEAT["backbones"]
    return {
        "size": int(FEAT["image_size"]),
        "arch": b["vision"]["arch"],
        "epochs": int(PRETRAIN["epochs"]),
    }


def knob_settings(knob):
    """(label, number for the log axis, is_default, path wildcards) of each setting."""
    out = []
    for value in COST_KNOB_CONFIG[knob]["values"]:
        if knob in ("presses", "tactile_resolution"):
            w = sim_default()
            if knob == "presses":
                w["presses"], label, num = int(value), str(int(value)), int(value)
            else:
                w["tactile"] = label = _hw(value)
                num = int(value[0])
            is_default = w == sim_default()
        else:
            w = features_default()
            if knob == "image_size":
                w["size"], label, num = int(value), str(int(value)), int(value)
            elif knob == "backbone_arch":
                w["arch"], label = str(value), str(value)
                num = ARCHS[str(value)].embed_dim
            else:
                w["epochs"], label, num = int(value), str(int(value)), int(value)
            is_default = w == features_default() and (
                FEAT["backbones"]["tactile"]["arch"] == w["arch"]
            )
        out.append((label, num, is_default, w))
    return out


def sim_setting_jobs(w):
    """The benchmark files of one simulation setting's jobs (what its seconds sum)."""
    d = f"presses~{w['presses']}/tactile~{w['tactile']}"
    return [
        f"results/benchmarks/cost_simulate_corpus/{d}/0.tsv",
        f"results/benchmarks/cost_merge_corpus/{d}.tsv",
        f"results/benchmarks/cost_background_subtract/{d}/{PROBE_VARIANT}.tsv",
        f"results/benchmarks/cost_sim_features/{d}/vision.tsv",
        f"results/benchmarks/cost_sim_features/{d}/tactile.tsv",
        f"results/benchmarks/cost_sim_probe/{d}.tsv",
    ]


def features_setting_jobs(w):
    d = f"size~{w['size']}/arch~{w['arch']}/epochs~{w['epochs']}"
    return [
        *(f"results/benchmarks/cost_pretrain_backbone/{d}/{m}.tsv" for m in MODALITIES),
        *(f"results/benchmarks/cost_features_extract/{d}/{m}.tsv" for m in MODALITIES),
        f"results/benchmarks/cost_pretrained_vs_random/{d}.tsv",
    ]


def sim_path(w, what):
    """A file of a simulation setting's folder (w: wildcards or a dict)."""
    return SIM_DIR.format(presses=w["presses"], tactile=w["tactile"]) + what


def knob_plan(knob):
    """What the points script needs per setting: label, number, default flag, the metrics
    edge (or pretrained-vs-random table) and the benchmark files."""
    plan = []
    for label, num, is_default, w in knob_settings(knob):
        if knob in ("presses", "tactile_resolution"):
            metrics = sim_path(w, "metrics.parquet")
            jobs = sim_setting_jobs(w)
        else:
            metrics = FEAT_DIR.format(**w) + "pretrained_vs_random.parquet"
            jobs = features_setting_jobs(w)
        plan.append(
            {
                "label": label,
                "setting": num,
                "is_default": is_default,
                "metrics": metrics,
                "benchmarks": jobs,
                "pretraining": int(w.get("epochs", 0)) > 0,
            }
        )
    return plan


def sim_corpus(w):
    """The reduced corpus of a simulation setting: the base corpus's first n samples (same
    name, seed and sample_ids), one shard, the setting's presses and tactile frame size.
    """
    h, wd = (int(v) for v in w.tactile.split("x"))
    return {
        "name": SIM_BASE,
        **CORPORA[SIM_BASE],
        "n": int(SIM_SWEEP["n"]),
        "shards": 1,
        "presses": int(w.presses),
        "tactile_size": [h, wd],
    }
