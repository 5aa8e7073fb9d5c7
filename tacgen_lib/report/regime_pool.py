"""The regime against the size of its unlabelled pool N_P, for the report page *Where generated
touch helps* (`tacgen_lib.report.regime`): each rung's Delta against nonlinear V as the pool
grows, with the look oracle's as the reference and the smallest rho's as the control that must
stay flat (there the look says nothing of the material, so no rung may gain); the verdict read
from it (`pool_verdict`), the table (`pool_table`) and the figure (`pool_curve_figure`).

A rung *gains* at a pool size where the replicates' (seed x labelled draw) interval of its
Delta against nonlinear V, read as one, lies above 0 (`regime_arms.gains`, the rule the
ladder's verdict decides by): so every replicate's CI lies above 0 and the replicates agree.
Every replicate's CI above 0 alone is looser than it reads on an R² target, where a negligible
Delta with tight paired CIs passes it at the smallest rho. The table shows both (the interval
and how many replicates' CIs lie above / below 0). The curve is read at the smallest labelled set at which
the look oracle gains (`reading_n_labelled`): generated touch should help most where labels are
few, but on too few the probe shows no gain at all, not even the oracle's; with the linear
probe every rung of the ladder uses.

The positive control (`generate.look_control`, rule regime_look_control) runs the same rungs
but the diffusion generator's on touch that is the look's mean real touch plus noise at a
stated signal-to-noise ratio: there the learnt rungs must begin to gain as the pool grows.
Each function takes its `seed_view` as ``control`` and shows it apart from the rho grid
(same rho as the grid's largest, other touch).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pandas as pd

from tacgen_lib.report import format as fmt
from tacgen_lib.report.regime_arms import RUNG_LABELS, arm_rows, gains
from tacgen_lib.report.regime_figures import panel_axes
from tacgen_lib.report.regime_hypotheses import replicate_words

if TYPE_CHECKING:  # pyplot is imported where a figure is drawn
    import matplotlib.pyplot as plt

__all__ = [
    "CURVE_RUNGS",
    "DIFFUSION_RUNGS",
    "LEARNT_RUNGS",
    "first_gain",
    "pool_curve_figure",
    "pool_table",
    "pool_verdict",
    "reading_n_labelled",
]

#: Rungs that learn a V -> T map from the pool without diffusion (`generate.ladder.LADDER`).
LEARNT_RUNGS = ("knn", "ridge", "kernel_ridge")
#: The diffusion generator's rungs: its mean over samples and one sample.
DIFFUSION_RUNGS = ("gen_mean", "v_tgen")
#: The curve's lines, top of the ladder first: the look oracle is the reference.
CURVE_RUNGS = ("look_oracle", *LEARNT_RUNGS, *DIFFUSION_RUNGS)
#: A line's colour and style in `pool_curve_figure`.
_STYLE = {
    "look_oracle": ("#ff7f0e", "--"),
    "knn": ("#9467bd", "-"),
    "ridge": ("#1f77b4", "-"),
    "kernel_ridge": ("#17becf", "-"),
    "gen_mean": ("#8c564b", "-"),
    "v_tgen": ("#d62728", "-"),
}


def _curve(view: pd.DataFrame, target: str, rho: float, n_labelled: int, rung: str):
    """One rung's `seed_view` rows (linear probe) at (target, rho, N_L), by pool size."""
    sub = view[
        (view["target"] == target) & (view["rho"] == rho) & (view["n_labelled"] == n_labelled)
    ]
    return arm_rows(sub, rung, "linear").sort_values("n_pool")


def _first_gain_row(
    view: pd.DataFrame, target: str, rho: float, n_labelled: int, rungs: tuple[str, ...]
) -> tuple[int, str, pd.Series] | None:
    """`first_gain` with the rung's `seed_view` row there."""
    curves = {rung: _curve(view, target, rho, n_labelled, rung) for rung in rungs}
    for n_p in sorted(view["n_pool"].unique()):
        for rung, curve in curves.items():
            at = curve[curve["n_pool"] == n_p]
            if not at.empty and gains(at.iloc[0]):
                return int(n_p), rung, at.iloc[0]
    return None


def first_gain(
    view: pd.DataFrame, target: str, rho: float, n_labelled: int, rungs: tuple[str, ...]
) -> tuple[int, str] | None:
    """The smallest pool size at which one of `rungs` gains over nonlinear V over the
    replicates (`regime_arms.gains`) at (target, rho, N_L), and that rung (the highest on the
    ladder there); None where none does at any pool size."""
    found = _first_gain_row(view, target, rho, n_labelled, rungs)
    return None if found is None else found[:2]


def reading_n_labelled(view: pd.DataFrame, target: str, rho: float) -> int:
    """The labelled-set size the curve of `target` at `rho` is read at: the smallest N_L at
    which the look oracle gains over nonlinear V over the replicates at some pool size (on
    fewer labels the probe may lack the power to show any gain, so no rung could show one),
    or the smallest N_L where it gains at none."""
    sizes = sorted(int(n) for n in view.loc[view["target"] == target, "n_labelled"].unique())
    for n_l in sizes:
        if first_gain(view, target, rho, n_l, ("look_oracle",)) is not None:
            return n_l
    return sizes[0]


def _first_words(
    found: tuple[int, str, pd.Series] | None, rungs: tuple[str, ...], what: str, largest: int
) -> str:
    """The verdict's words for `_first_gain_row`'s `found` among `rungs`."""
    if found is None:
        names = ", ".join(RUNG_LABELS[r] for r in rungs)
        return (
            f"no {what} ({names}) gains over nonlinear V over the replicates at any N_P up to "
            f"{largest}"
        )
    n_p, rung, row = found
    return (
        f"a {what} first gains over nonlinear V over the replicates at N_P = {n_p} "
        f"({RUNG_LABELS[rung]}: {replicate_words(row, 'nonlinear_v')})"
    )


def _control_words(
    control: pd.DataFrame, target: str, n_l: int, pools: list[int], snr: float | None
) -> str:
    """The positive control's sentence for `target`: where a learnt rung first gains, and
    each learnt rung's Delta at the smallest and the largest pool."""
    rho = control["rho"].max()
    built = "the look's mean real touch + noise" + (f" at SNR {snr:g}" if snr else "")
    found = _first_gain_row(control, target, rho, n_l, LEARNT_RUNGS)
    first = _first_words(found, LEARNT_RUNGS, "learnt rung", pools[-1])
    ends = []
    for rung in LEARNT_RUNGS:
        curve = _curve(control, target, rho, n_l, rung)
        if len(curve) >= 2:
            ends.append(
                f"{RUNG_LABELS[rung]} {fmt.signed(curve['delta_vs_nonlinear_v'].iloc[0])} → "
                f"{fmt.signed(curve['delta_vs_nonlinear_v'].iloc[-1])}"
            )
    if found is not None:
        reading = ""
    elif first_gain(control, target, rho, n_l, ("look_oracle",)) is None:
        reading = (
            " On the control's touch the look oracle gains at no pool size either: the probe "
            f"on {n_l} labels lacks the power to show a gain here, so the control says nothing "
            "of the rungs at this N_L."
        )
    else:
        reading = (
            " The control fails: no learnt rung gains even where the effect is built in, so "
            "the curve's 'none' above does not say the real touch lacks it."
        )
    return (
        f"Positive control of the curve ({target}, ρ = {rho:g}, N_L = {n_l}, touch = {built}): "
        f"{first}; Δ vs nonlinear V from N_P = {pools[0]} to {pools[-1]}: "
        f"{'; '.join(ends) or 'one pool size'}.{reading}"
    )


def pool_verdict(
    view: pd.DataFrame, control: pd.DataFrame | None = None, snr: float | None = None
) -> list[str]:
    """The curve's verdict, per target at the largest rho and the N_L it is read at
    (`reading_n_labelled`: the smallest at which the look oracle gains): the smallest
    pool at which a learnt rung (`LEARNT_RUNGS`) and at which the diffusion model
    (`DIFFUSION_RUNGS`) gains over the replicates (`first_gain`), or that none does up to the
    largest pool; the look oracle's Delta at the largest pool as the reference (and that the
    curve cannot show anything where the oracle gains at no pool size); and whether the
    smallest rho's curve stays flat (no rung gains there at any pool size); with `control`
    (the positive control's `seed_view`, built at `snr`), where its learnt rungs first gain.
    One sentence saying so where the regime ran one pool size."""
    pools = sorted(int(n) for n in view["n_pool"].unique())
    if len(pools) < 2:
        return [
            f"One pool size ran (N_P = {pools[0]}): the curve against the pool size needs "
            "two or more (regime.n_pool)."
        ]
    rhos = sorted(view["rho"].unique())
    rho_hi, rho_lo = rhos[-1], rhos[0]
    out = []
    for target in sorted(view["target"].unique()):
        n_l = reading_n_labelled(view, target, rho_hi)
        where = f"{target}, ρ = {rho_hi:g}, N_L = {n_l}, N_P {pools[0]}–{pools[-1]}"
        oracle = _curve(view, target, rho_hi, n_l, "look_oracle")
        # its looks get finer as the pool grows (docs/regime.md): both ends of its curve
        reference = (
            f"the look oracle − nonlinear V at N_P = {pools[-1]}: "
            f"{replicate_words(oracle.iloc[-1], 'nonlinear_v')}"
            + (
                f" (at N_P = {int(oracle['n_pool'].iloc[0])}: "
                f"{fmt.signed(oracle['delta_vs_nonlinear_v'].iloc[0])})"
                if len(oracle) > 1
                else ""
            )
            if not oracle.empty
            else "no look oracle ran"
        )
        found = _first_gain_row(view, target, rho_hi, n_l, LEARNT_RUNGS)
        learnt = _first_words(found, LEARNT_RUNGS, "learnt rung", pools[-1])
        found = _first_gain_row(view, target, rho_hi, n_l, DIFFUSION_RUNGS)
        diffusion = _first_words(found, DIFFUSION_RUNGS, "diffusion rung", pools[-1])
        # the reference must itself gain somewhere, else no rung could show what it adds
        void = (
            ""
            if any(gains(r) for _, r in oracle.iterrows())
            else " The look oracle gains over the replicates at no pool size, so the curve "
            "cannot show what a generator would add."
        )
        out.append(f"Pool size ({where}): {learnt}; {diffusion}; {reference}.{void}")
        if control is not None and target in set(control["target"]):
            out.append(_control_words(control, target, n_l, pools, snr))
        if rho_lo == rho_hi:
            out.append(f"Pool size ({target}): one ρ ran, so the curve has no flat control.")
            continue
        spoilers = [
            f"{RUNG_LABELS[rung]} at N_P = {int(r.n_pool)}"
            for rung in CURVE_RUNGS[1:]
            for _, r in _curve(view, target, rho_lo, n_l, rung).iterrows()
            if gains(r)
        ]
        out.append(
            f"Pool-size control ({target}, ρ = {rho_lo:g}, where the look says nothing of the "
            "material): "
            + (
                "flat, no rung gains over nonlinear V over the replicates at any N_P."
                if not spoilers
                else "not flat: "
                + "; ".join(spoilers)
                + " gain over the replicates, a gain that is not the look's: the curve above "
                "does not show what generated touch adds."
            )
        )
    return out


def pool_table(view: pd.DataFrame, control: pd.DataFrame | None = None) -> pd.DataFrame:
    """Rung x pool size at the smallest and largest rho, and at the smallest and largest N_L
    and the one each target's curve is read at (`reading_n_labelled`, whose figures the
    verdict gives): each rung's (linear probe) mean Delta against nonlinear V with the
    replicates' interval read as one and how many replicates' CIs lie above / below 0, one
    column per pool size; with `control` (the
    positive control's `seed_view`), its rungs after each target's, touch 'look + noise'."""
    rhos = sorted(view["rho"].unique())
    ls = sorted(view["n_labelled"].unique())
    pools = sorted(int(n) for n in view["n_pool"].unique())
    out = []
    for target in sorted(view["target"].unique()):
        sizes = sorted({ls[0], reading_n_labelled(view, target, rhos[-1]), ls[-1]})
        panels = [(view, rho, "real") for rho in sorted({rhos[0], rhos[-1]})]
        if control is not None and target in set(control["target"]):
            panels.append((control, control["rho"].max(), "look + noise (control)"))
        for source, rho, touch in panels:
            for n_l in sizes:
                for rung in CURVE_RUNGS:
                    curve = _curve(source, target, rho, n_l, rung)
                    if curve.empty:
                        continue
                    row = {"target": target, "touch": touch, "ρ": f"{rho:g}", "N_L": int(n_l)}
                    row["rung"] = RUNG_LABELS[rung]
                    for n_p in pools:
                        at = curve[curve["n_pool"] == n_p]
                        row[f"N_P = {n_p}"] = _cell(at.iloc[0]) if len(at) else fmt.MISSING
                    out.append(row)
    return pd.DataFrame(out)


def _cell(r: pd.Series) -> str:
    n = int(r["n_seeds"])
    up, down = int(r["above_vs_nonlinear_v"]), int(r["below_vs_nonlinear_v"])
    interval = (
        f"[{fmt.signed(r['rep_low_vs_nonlinear_v'])}, {fmt.signed(r['rep_high_vs_nonlinear_v'])}]"
    )
    return f"{fmt.signed(r['delta_vs_nonlinear_v'])} {interval} {up}/{n} ↑, {down}/{n} ↓"


def _pool_panel(ax, view: pd.DataFrame, target: str, rho: float, n_l: int, pools: list[int]):
    """One panel of `pool_curve_figure`: each rung's curve at (target, rho, N_L)."""
    ax.axhline(0.0, color="#444444", linewidth=0.8)
    for k, rung in enumerate(CURVE_RUNGS):
        curve = _curve(view, target, rho, n_l, rung)
        if curve.empty:
            continue
        colour, style = _STYLE[rung]
        # a small shift per rung keeps the bars of one pool size apart
        x = curve["n_pool"].to_numpy(dtype=float) * 2.0 ** (0.05 * (k - 2.5))
        y = curve["delta_vs_nonlinear_v"].to_numpy(dtype=float)
        low = y - curve["rep_low_vs_nonlinear_v"].to_numpy(dtype=float)
        high = curve["rep_high_vs_nonlinear_v"].to_numpy(dtype=float) - y
        ax.errorbar(
            x,
            y,
            yerr=[low, high],
            color=colour,
            linestyle=style,
            capsize=2,
            linewidth=1.2,
            label=RUNG_LABELS[rung],
        )
        full = [gains(r) for _, r in curve.iterrows()]
        ax.scatter(
            x,
            y,
            s=22,
            zorder=3,
            edgecolors=colour,
            facecolors=[colour if f else "white" for f in full],
        )
    ax.set_xscale("log", base=2)
    ax.set_xlim(pools[0] / 1.5, pools[-1] * 1.5)
    ax.set_xticks(pools, [str(n) for n in pools])
    ax.minorticks_off()
    ax.set_xlabel("N_P unlabelled pool rows")
    ax.set_ylabel("Δ vs nonlinear V")
    ax.grid(alpha=0.3)


def pool_curve_figure(view: pd.DataFrame, control: pd.DataFrame | None = None) -> plt.Figure:
    """Delta against nonlinear V per rung against the pool size, at the N_L each target's curve
    is read at (`reading_n_labelled`), one panel per target x (largest rho, smallest rho, and
    the positive control where `control` holds its `seed_view`); bars: the replicates'
    interval read as one; a filled marker: that interval above 0 (a gain)."""
    targets = sorted(view["target"].unique())
    rhos = sorted(view["rho"].unique())
    columns = [(view, r, "") for r in ([rhos[-1]] if rhos[0] == rhos[-1] else [rhos[-1], rhos[0]])]
    if control is not None and len(control):
        columns.append((control, control["rho"].max(), "positive control\nlook + noise, "))
    pools = sorted(int(n) for n in view["n_pool"].unique())
    # three panels across keep to the report viewer's width
    width = 4.2 if len(columns) < 3 else 3.1
    fig, axes = panel_axes(len(targets), len(columns), (width, 3.0), legend_height=1.0)
    for i, target in enumerate(targets):
        n_l = reading_n_labelled(view, target, rhos[-1])
        for j, (source, rho, what) in enumerate(columns):
            _pool_panel(axes[i][j], source, target, rho, n_l, pools)
            axes[i][j].set_title(f"{target}, {what}ρ = {rho:g}, N_L = {n_l}", fontsize=9)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=9)
    if len(pools) < 2:
        fig.suptitle("one pool size ran: a curve needs two or more (regime.n_pool)", fontsize=9)
    return fig
