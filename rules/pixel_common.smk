"""Helpers of the pixel generators (their corpora, arms and paths); included by pixel.smk."""

from tacgen_lib.generate.pixel.utility import GENERATORS, ddpm_arm

# a config without the section (one given with --replace-workflow-config) runs no pixel stage
PIXEL = config.get("pixel") or {"corpora": {}, "curve": {"corpora": {}}}
PIXEL_CORPORA = list(PIXEL["corpora"])
PIXEL_CURVE = PIXEL["curve"]
PIXEL_CURVE_CORPORA = list(PIXEL_CURVE["corpora"])
# every corpus a pixel generator is trained on: the judged ones, then the curve's
PIXEL_TRAIN_CORPORA = PIXEL_CORPORA + [
    c for c in PIXEL_CURVE_CORPORA if c not in PIXEL_CORPORA
]
PIXEL_DIR = "results/pixel"
PIXEL_REPORT = "results/report/pixel"
PIXEL_GENERATOR = f"{PIXEL_DIR}/{{corpus}}/{{generator}}/seed~{{seed}}"
PIXEL_ARM = f"{PIXEL_DIR}/{{corpus}}/arms/{{arm}}/seed~{{seed}}/frames.parquet"
PIXEL_EVAL = f"{PIXEL_DIR}/{{corpus}}/seed~{{seed}}"
PIXEL_POINT = f"{PIXEL_DIR}/curve/{{corpus}}/seed~{{seed}}/p~{{fraction}}.parquet"
PIXEL_ITEMS = {
    "architecture": "html",
    "calibration": "html",
    "curve": "png",
    "scatter": "png",
    **{f"filmstrip_{g}": "png" for g in GENERATORS},
}
# the DDIM cells of the pixel DDPM, as arm names (ddpm_w<w>_s<steps>)
PIXEL_DDPM_ARMS = [
    ddpm_arm(w, s)
    for w in (PIXEL.get("ddpm_cells") or {"guidance": []})["guidance"]
    for s in PIXEL["ddpm_cells"]["steps"]
]
PIXEL_JUDGED_ARMS = ["pix2pix"] + PIXEL_DDPM_ARMS
# the curve's generator: pix2pix, or the pixel DDPM's first cell
PIXEL_CURVE_ARM = (
    "pix2pix"
    if PIXEL_CURVE.get("generator", "pix2pix") == "pix2pix"
    else PIXEL_DDPM_ARMS[0]
)

for _c in PIXEL_TRAIN_CORPORA:
    if _c not in CORPORA:
        raise ValueError(
            f"config pixel: {_c!r} is not a corpus (have {sorted(CORPORA)})"
        )
    if _c in (config["splits"].get("by_object") or {}):
        raise ValueError(
            f"config pixel: corpus {_c!r} is split by object; the pixel generators need the "
            "random train/val/test split"
        )
if PIXEL_TRAIN_CORPORA and not PIXEL_DDPM_ARMS:
    raise ValueError(
        "config pixel.ddpm_cells: needs at least one guidance and one steps value"
    )
if PIXEL_CURVE_CORPORA and config["probes"]["heads"]["variant"] != "clip128":
    raise ValueError(
        "config pixel.curve: the generators imitate clip128 frames; probes.heads.variant "
        f"is {config['probes']['heads']['variant']!r}"
    )


def pixel_arms(corpus):
    """The arms sampled on a corpus: every judged arm where utility is judged, else the curve's."""
    return PIXEL_JUDGED_ARMS if corpus in PIXEL_CORPORA else [PIXEL_CURVE_ARM]


def arm_generator_name(arm):
    return "pix2pix" if arm == "pix2pix" else "ddpm"


def pixel_generators(corpus):
    return sorted({arm_generator_name(a) for a in pixel_arms(corpus)})


def pixel_seeds():
    return [str(s) for s in PIXEL.get("seeds", [])]


def pixel_arm_edge(corpus, arm, seed):
    return PIXEL_ARM.format(corpus=corpus, arm=arm, seed=seed)


def pixel_eval_files(name):
    return [
        f"{PIXEL_EVAL}/{name}".format(corpus=c, seed=s)
        for c in PIXEL_CORPORA
        for s in pixel_seeds()
    ]


def pixel_fraction_text(p):
    return f"{float(p):g}"


def pixel_points():
    return [
        PIXEL_POINT.format(corpus=c, seed=s, fraction=pixel_fraction_text(p))
        for c in PIXEL_CURVE_CORPORA
        for s in pixel_seeds()
        for p in PIXEL_CURVE["fractions"]
    ]


def pixel_weights():
    return [
        f"{PIXEL_GENERATOR}/generator.safetensors".format(corpus=c, generator=g, seed=s)
        for c in PIXEL_TRAIN_CORPORA
        for g in pixel_generators(c)
        for s in pixel_seeds()
    ]


def pixel_benchmarks(rule_name):
    """The benchmark files of one pixel rule (the page's seconds)."""
    if rule_name == "train_pixel_generator":
        return [
            f"results/benchmarks/train_pixel_generator/{c}/{g}/{s}.tsv"
            for c in PIXEL_TRAIN_CORPORA
            for g in pixel_generators(c)
            for s in pixel_seeds()
        ]
    return [
        f"results/benchmarks/sample_pixel_generator/{c}/{a}/{s}.tsv"
        for c in PIXEL_TRAIN_CORPORA
        for a in pixel_arms(c)
        for s in pixel_seeds()
    ]


if PIXEL_TRAIN_CORPORA and pixel_seeds():
    TARGETS += [f"{PIXEL_REPORT}/{n}.{e}" for n, e in PIXEL_ITEMS.items()]
    TARGETS += ["results/pixel/summary.parquet"]
    EDGES += pixel_eval_files("evaluation.parquet")
    EDGES += pixel_eval_files("reconstruction.parquet")
    EDGES += pixel_points()
    EDGES += [
        pixel_arm_edge(c, a, s)
        for c in PIXEL_TRAIN_CORPORA
        for a in pixel_arms(c)
        for s in pixel_seeds()
    ]
