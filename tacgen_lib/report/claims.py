"""Every sentence the report states about a number, generated from that number.

One function per claim, used by every page that states it, so two pages cannot say different
things about the same figures. Each returns a short sentence (or a short verdict for a table
cell); none reads files. The words follow fixed rules:

- an interval *above 0* has its lower bound > 0; *below 0*, its upper bound < 0; an interval that
  has 0 as a bound *touches 0* and, like one containing 0, does not exclude it;
- a point without an interval (one seed, one run) is never called significant;
- "within the uncertainty" has one meaning everywhere: the cheaper setting's value lies inside
  the dearer setting's interval (the gain is not measurable at the dearer point's precision).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from tacgen_lib.report import format as fmt

__all__ = [
    "interval_side",
    "mean_t_interval",
    "seeds_interval",
    "delta_verdict",
    "probe_verdict",
    "generation_verdict",
    "ridge_verdict",
    "PAIRING_P",
    "pairing_decision",
    "gain_within_uncertainty",
    "ceiling_decision",
    "ceiling_verdict",
    "proportion_interval",
    "proportion_with_ci",
    "below_majority",
    "extreme_flag",
    "still_falling",
]


def interval_side(lo: float, hi: float) -> str:
    """Where a 95 % interval lies against 0: "above", "below", "touches" (0 is a bound),
    "spans" (0 strictly inside), or "none" (no interval)."""
    if fmt.is_missing(lo) or fmt.is_missing(hi):
        return "none"
    if lo > 0:
        return "above"
    if hi < 0:
        return "below"
    if lo == 0 or hi == 0:
        return "touches"
    return "spans"


def mean_t_interval(values) -> tuple[float, float, float]:
    """The mean of `values` (NaNs dropped) and its 95 % t-interval; the interval is NaN with
    fewer than two values."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan, math.nan
    m = float(v.mean())
    if v.size < 2:
        return m, math.nan, math.nan
    from scipy import stats  # here: most claims need no SciPy

    h = float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return m, m - h, m + h


def seeds_interval(deltas, lows, highs) -> tuple[float, float, float]:
    """One difference measured once per replicate (a training seed, a labelled draw), each
    with its own 95 % interval over the test rows, read as one: the mean over the replicates
    and an interval that holds every replicate's own interval (a difference one replicate does
    not show is not called real) and, from three replicates on, the mean's t-interval over
    them (`mean_t_interval`: the replicates' spread; the test rows they share are in their own
    intervals, not in the spread). Two replicates give a t-interval of one degree of freedom,
    whose width is the noise of one difference: their two intervals decide alone. One
    replicate: its own interval.

    A decision read from it holds whichever of the replicates had been drawn, and a rerun
    that draws them again (other CPU kernels carry a last-bit difference through training as
    another seed would) moves it only where the evidence is at its edge.
    """
    d = np.asarray(deltas, dtype=np.float64)
    lo_s, hi_s = np.asarray(lows, dtype=np.float64), np.asarray(highs, dtype=np.float64)
    keep = np.isfinite(d)
    if not keep.any():
        return math.nan, math.nan, math.nan
    d, lo_s, hi_s = d[keep], lo_s[keep], hi_s[keep]
    if d.size == 1:
        return float(d[0]), float(lo_s[0]), float(hi_s[0])
    lo, hi = float(lo_s.min()), float(hi_s.max())
    if d.size >= 3:
        _, t_lo, t_hi = mean_t_interval(d)
        lo, hi = min(lo, t_lo), max(hi, t_hi)
    return float(d.mean()), lo, hi


def delta_verdict(delta: float, lo: float, hi: float, *, what: str = "V+T") -> str:
    """One sentence on a difference with its interval: does it exclude 0, and in which
    direction."""
    if fmt.is_missing(delta):
        return "not computed."
    side = interval_side(lo, hi)
    d = fmt.signed(delta)
    if side == "none":
        return f"Δ = {d} from one point: no interval, so no claim either way."
    ci = f"[{fmt.signed(lo)}, {fmt.signed(hi)}]"
    if side == "above":
        return f"{what} helps: Δ = {d}, 95 % CI {ci} above 0."
    if side == "below":
        return f"{what} hurts: Δ = {d}, 95 % CI {ci} below 0."
    if side == "touches":
        return f"No measurable difference: Δ = {d}, 95 % CI {ci} touches 0."
    return f"No measurable difference: Δ = {d}, 95 % CI {ci} contains 0."


def probe_verdict(
    delta: float,
    lo: float,
    hi: float,
    *,
    null_corpus: bool,
    criterion_met: bool | None,
    delta_ctrl: float,
) -> str:
    """The verdict on one probe family's V vs V+T comparison, read against its control
    (`delta_ctrl`: the mean Δ with touch permuted across rows) and the paper's criterion
    (Δ >= 0.03, CI above 0, Δ_ctrl < Δ).

    On a null corpus touch carries no label: a gain there is a defect of the pipeline, and the
    expected outcome is an interval that does not lie above 0."""
    side = interval_side(lo, hi)
    base = delta_verdict(delta, lo, hi)
    if null_corpus:
        if side == "above":
            return "UNEXPECTED: touch helps on the null corpus, where it carries no label. " + base
        return "As expected on the null corpus (touch carries no label): no gain. " + base
    if criterion_met is True:
        return (
            base + f" With touch permuted across rows Δ_ctrl = {fmt.signed(delta_ctrl)}: "
            "criterion met."
        )
    if criterion_met is False and side == "above":
        return (
            base + f" But a control reaches Δ_ctrl = {fmt.signed(delta_ctrl)}: criterion not met."
        )
    return base


def generation_verdict(
    gen: tuple[float, float, float], real: tuple[float, float, float], nonlinear: tuple[float, ...]
) -> str:
    """Generated touch against real touch and against the nonlinear V-only baseline (each a
    (Δ, lo, hi) triple of Δ against linear V)."""
    g_side, r_side = interval_side(*gen[1:]), interval_side(*real[1:])
    g = fmt.with_ci(*gen, sign=True)
    parts = []
    if g_side == "above":
        parts.append(f"Generated touch helps (Δ_gen {g})")
    else:
        parts.append(f"Generated touch does not help (Δ_gen {g})")
    r = fmt.with_ci(*real, sign=True)
    if r_side == "above" and g_side == "above":
        parts.append(f"so does real touch (Δ_real {r})")
    elif r_side == "above":
        parts.append(f"real touch does (Δ_real {r})")
    elif g_side == "above":
        parts.append(
            f"real touch does not (Δ_real {r}): a gain that real touch does not give is not "
            "touch's information (chance, or the probe)"
        )
    else:
        parts.append(f"nor does real touch (Δ_real {r})")
    text = "; ".join(parts) + "."
    if g_side == "above" and not fmt.is_missing(nonlinear[0]):
        n_side = interval_side(*nonlinear[1:])
        if n_side == "above" and nonlinear[0] >= gen[0]:
            text += (
                f" A nonlinear V-only probe gains as much ({fmt.signed(nonlinear[0])}): the gain "
                "is in the probe, not in generated touch."
            )
    return text


#: A paired difference with its interval: (Δ, lo, hi).
Interval = tuple[float, float, float]


def ridge_verdict(
    vs_ridge: Interval,
    pairing: Mapping[str, tuple[float, float]],
    pairing_p: float,
    gaps: Mapping[str, Interval] | None = None,
) -> str:
    """Generated touch against the simplest generator, ridge V->T, in two sentences.

    The probe: `vs_ridge` = (score(V + T_gen) - score(V + T_ridge), lo, hi). T_ridge is a
    linear function of V, so a linear probe gains nothing from it beyond V: an interval below
    0 says the generated vectors cost the probe more than they give. Fidelity: `pairing` maps
    "t_gen", "t_ridge" (ridge's conditional mean) and "t_ridge_residual" (the mean plus a
    sampled residual) to (matched-pair cosine, off-diagonal cosine) with the real test rows;
    what is paired is the gap between them (on a corpus where nothing is, both are equal).
    `pairing_p` is the diffusion samples' pairing-permutation p; `gaps` the paired
    differences of their gap from ridge's mean ("ridge") and from ridge + residual
    ("ridge_residual") over the test rows, with intervals (`pairing_decision`). A sample
    carries the conditional spread that a mean averages out, so a sampler is judged against
    the residual arm, and the mean bounds what any sample of the same map reaches."""
    side = interval_side(*vs_ridge[1:])
    d = fmt.with_ci(*vs_ridge, sign=True)
    if side == "below":
        probe = (
            f"V + T_gen scores below V + ridge V→T (Δ_gen − ridge {d}): the samples cost the probe."
        )
    elif side == "above":
        probe = f"V + T_gen beats V + ridge V→T in the probe (Δ_gen − ridge {d})."
    else:
        probe = f"In the probe V + T_gen and V + ridge V→T do not differ measurably ({d})."
    gap = {k: m - off for k, (m, off) in pairing.items()}
    cos = (
        f"matched minus off-diagonal cosine {gap['t_gen']:+.3f}, against {gap['t_ridge']:+.3f} "
        f"for ridge's conditional mean and {gap['t_ridge_residual']:+.3f} for ridge + a sampled "
        "residual"
    )
    gaps = gaps or {}
    diff = "; ".join(
        f"{name} {fmt.with_ci(*gaps[k], sign=True)}"
        for k, name in (("ridge_residual", "− ridge's samples"), ("ridge", "− ridge's mean"))
        if k in gaps and not fmt.is_missing(gaps[k][0])
    )
    cos = f"{cos}; {diff}" if diff else cos
    paired = pairing_decision(pairing, pairing_p, gaps)
    if paired == "not measurably paired":
        fid = (
            f"Its samples are not measurably paired with the real rows (pairing p "
            f"{pairing_p:.3f}; {cos}): nothing row-specific of real touch is in them."
        )
    elif paired == "less paired than ridge's samples":
        fid = (
            f"Its samples are less paired with real touch than ridge's ({cos}): the diffusion "
            "generator has learnt less of the V→T map than a linear regression."
        )
    elif paired == "paired between ridge's samples and its mean":
        fid = (
            f"Its samples are paired with real touch better than ridge's samples but not its "
            f"mean ({cos}): a sample carries the spread a mean averages out."
        )
    elif paired == "paired better than ridge's mean":
        fid = f"Its samples are paired with real touch better than ridge's mean ({cos})."
    else:
        fid = (
            f"Its samples are paired with real touch as ridge's are, within the test rows' "
            f"uncertainty ({cos})."
        )
    return f"{probe} {fid}"


#: The pairing-permutation p below which generated samples count as paired with real touch.
PAIRING_P = 0.05


def pairing_decision(
    pairing: Mapping[str, tuple[float, float]],
    pairing_p: float,
    gaps: Mapping[str, Interval] | None = None,
) -> str:
    """How the diffusion samples are paired with the real rows (`ridge_verdict`'s fidelity
    sentence): ``not measurably paired`` (pairing p missing or above `PAIRING_P`); else, read
    by the intervals of their gap's paired differences from ridge's (`gaps`: "ridge_residual",
    ridge + a sampled residual; "ridge", ridge's mean): ``less paired than ridge's samples``
    (below the residual arm's), ``paired better than ridge's mean`` (above the mean's),
    ``paired between ridge's samples and its mean`` (above the residual arm's, below the
    mean's), or ``paired as ridge's samples`` (no interval excludes 0: the test rows cannot
    tell them apart). Without `gaps` (an older edge), the gaps' points decide (`pairing`)."""
    if fmt.is_missing(pairing_p) or pairing_p > PAIRING_P:
        return "not measurably paired"
    if gaps:
        vs_res = interval_side(*gaps["ridge_residual"][1:])
        vs_mean = interval_side(*gaps["ridge"][1:])
        if vs_res == "below":
            return "less paired than ridge's samples"
        if vs_mean == "above":
            return "paired better than ridge's mean"
        if vs_res == "above" and vs_mean == "below":
            return "paired between ridge's samples and its mean"
        return "paired as ridge's samples"
    gap = {k: m - off for k, (m, off) in pairing.items()}
    if gap["t_gen"] < gap["t_ridge_residual"]:
        return "less paired than ridge's samples"
    if gap["t_gen"] < gap["t_ridge"]:
        return "paired between ridge's samples and its mean"
    return "paired better than ridge's mean"


def gain_within_uncertainty(cheap_value: float, dear_lo: float, dear_hi: float) -> bool:
    """Whether the cheaper setting's value lies inside the dearer setting's interval: then the
    gain the dearer setting buys is not measurable at its precision. False without an interval.
    """
    if any(fmt.is_missing(x) for x in (cheap_value, dear_lo, dear_hi)):
        return False
    return bool(dear_lo <= cheap_value <= dear_hi)


def ceiling_decision(score: float, lo: float, hi: float, ceiling: float) -> str:
    """Where a V-only policy's success sits against the vision-only ceiling, read by its
    interval: ``not computed``, ``above the ceiling`` (the interval wholly above: a defect),
    ``reaches the ceiling`` (the ceiling inside the interval, whichever side the point lies:
    a point a hair above or below it is the same finding) or ``below the ceiling``."""
    if fmt.is_missing(score) or fmt.is_missing(ceiling):
        return "not computed"
    if not fmt.is_missing(lo) and lo > ceiling:
        return "above the ceiling"
    if fmt.is_missing(hi) or hi >= ceiling:
        return "reaches the ceiling"
    return "below the ceiling"


def ceiling_verdict(
    score: float, lo: float, hi: float, ceiling: float, *, what: str = "V-only"
) -> str:
    """Where a V-only policy's success sits against the vision-only ceiling (the expected
    success of the best force given what vision sees; `ceiling_decision`). A point estimate
    above the ceiling with an interval reaching below it is sampling noise; an interval wholly
    above it is a defect."""
    s = fmt.with_ci(score, lo, hi)
    c = fmt.number(ceiling)
    decided = ceiling_decision(score, lo, hi, ceiling)
    if decided == "not computed":
        return f"{what}: not computed."
    if decided == "above the ceiling":
        return (
            f"UNEXPECTED: {what} success {s} lies above the vision-only ceiling {c}: vision "
            "must see more than the ceiling assumes."
        )
    if decided == "reaches the ceiling" and score > ceiling:
        return (
            f"{what} success {s} is at the vision-only ceiling {c}: its point is above it by "
            "sampling noise only (the interval reaches below)."
        )
    if decided == "reaches the ceiling":
        return f"{what} success {s} reaches the vision-only ceiling {c} within its interval."
    return f"{what} success {s} stays below the vision-only ceiling {c}."


def proportion_interval(
    successes: int, n: int, z: float = 1.959963984540054
) -> tuple[float, float]:
    """Wilson score interval of a proportion (95 % by default). Unlike a bootstrap, it does not
    collapse to a point when every trial succeeds (or fails): 128 successes of 128 keep a
    lower end below 1."""
    if n <= 0:
        return math.nan, math.nan
    p = successes / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def proportion_with_ci(p: float, lo: float, hi: float, n: int) -> str:
    """A success rate with its bootstrap CI; where the bootstrap has no width (every trial the
    same outcome) the Wilson interval instead, saying so."""
    if not fmt.is_missing(lo) and lo == hi and n > 0:
        k = int(round(p * n))
        w_lo, w_hi = proportion_interval(k, n)
        return f"{fmt.with_ci(p, w_lo, w_hi)} (Wilson: all {k}/{n} alike)"
    return fmt.with_ci(p, lo, hi)


def extreme_flag(
    metric: str,
    v: float,
    vt: float,
    lo: float,
    hi: float,
    baseline: float = float("nan"),
    n_test: float = float("nan"),
) -> str:
    """Why a comparison's numbers are extreme, or "": an R² below −1 (the probe predicts worse
    than the train mean by more than the target's variance: too few rows for its features, or
    test rows outside the train range), or a Δ interval reaching beyond ±1 (wider than the
    metric's own range: Δ then measures one probe's failure, not what touch adds), or a V
    accuracy measurably below `baseline`, the majority-class rate: with `n_test` test rows, the
    accuracy's 95 % Wilson interval (`proportion_interval`) lies wholly below it, so a V that
    ties the majority within the test rows' sampling noise is not flagged on one machine and
    passed on another; without `n_test`, any V below it."""
    reasons = []
    if metric == "r2":
        low = [name for name, x in (("V", v), ("V+T", vt)) if not fmt.is_missing(x) and x < -1]
        if low:
            reasons.append(
                f"R² of {' and '.join(low)} below −1: worse than predicting the train mean"
            )
    if any(not fmt.is_missing(x) and abs(x) > 1 for x in (lo, hi)):
        reasons.append("Δ interval beyond ±1, wider than the metric's range")
    if metric == "accuracy" and below_majority(v, baseline, n_test):
        reasons.append(
            f"V accuracy {fmt.number(v)} below the majority-class rate "
            f"{fmt.number(baseline)}: the V probe does worse than always guessing the "
            "commonest train class"
        )
    return "; ".join(reasons)


def below_majority(v: float, majority: float, n_test: float = float("nan")) -> bool:
    """Whether an accuracy `v` on `n_test` rows lies measurably below the majority-class rate:
    its 95 % Wilson interval's upper bound is below it (any `v` below it where `n_test` is
    unknown). False where either is missing."""
    if fmt.is_missing(v) or fmt.is_missing(majority):
        return False
    if fmt.is_missing(n_test) or int(n_test) <= 0:
        return bool(v < majority)
    n = int(n_test)
    return bool(proportion_interval(int(round(v * n)), n)[1] < majority)


def still_falling(steps, losses, *, tail: float = 0.2, rel: float = 0.02) -> bool:
    """Whether a loss curve still falls at its end: over the last `tail` of its steps the
    validation loss dropped by more than `rel` of its value there (training stopped before it
    levelled off). False for a curve of fewer than 3 points."""
    s, y = np.asarray(steps, dtype=float), np.asarray(losses, dtype=float)
    keep = np.isfinite(s) & np.isfinite(y)
    s, y = s[keep], y[keep]
    if s.size < 3:
        return False
    order = np.argsort(s, kind="stable")
    s, y = s[order], y[order]
    start = s[-1] - tail * (s[-1] - s[0])
    before = y[s <= start]
    ref = before[-1] if before.size else y[0]
    return bool(ref - y[-1] > rel * abs(y[-1]))
