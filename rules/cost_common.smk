"""Cost of accuracy (DESIGN §7): the knob registry every rules/cost*.smk adds to.

A knob is swept when config `cost.knobs` lists it (config/cost.yaml); its points are
`results/cost/points/{knob}.parquet` (tacgen_lib.cost.points). Each cost*.smk registers the
knobs its rules write with `register_cost_knobs`; `free=True` marks knobs whose points come
from a stage's own grid at no extra job (the generator's steps and samplers, the policy's
width and epochs sweep), so the default run's page shows them too (`cost.grid_knobs: false`
leaves them out). `cost_points()` is the
page's input: an unknown name in `cost.knobs` stops the run with the registered names.
"""

from tacgen_lib.io.config import load_yaml as _load_yaml

COST = config.get("cost") or {}
COST_KNOB_CONFIG = COST.get("knobs") or {}
COST_POINTS = "results/cost/points/{knob}.parquet"
COST_KNOBS = {}  # knob -> stage, registered by rules/cost*.smk
COST_FREE_KNOBS = set()
# The embedded default marks each knob's default setting (a --configfile may widen a grid).
DEFAULT_CONFIG = _load_yaml(WORKFLOW_ROOT / "config" / "config.yaml")


def register_cost_knobs(stage, names, free=False):
    for name in names:
        COST_KNOBS[name] = stage
        if free:
            COST_FREE_KNOBS.add(name)


def cost_knob(name):
    """Config entry of a knob (its `values` and options), {} if not swept."""
    return COST_KNOB_CONFIG.get(name) or {}


def cost_knobs():
    """The knobs the page shows: every configured knob, then the free ones."""
    unknown = sorted(set(COST_KNOB_CONFIG) - set(COST_KNOBS))
    if unknown:
        raise ValueError(
            f"config cost.knobs: {unknown} are not knobs of this workflow "
            f"(known: {sorted(COST_KNOBS)})"
        )
    free = COST_FREE_KNOBS if COST.get("grid_knobs", True) else set()
    return [k for k in COST_KNOBS if k in COST_KNOB_CONFIG or k in free]


def cost_points(wildcards=None):
    return [COST_POINTS.format(knob=k) for k in cost_knobs()]
