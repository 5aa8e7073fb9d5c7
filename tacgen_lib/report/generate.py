"""Tables and figures of the generate stage (the report's *Generation* category).

This module owns the generation summary (the evaluation rows of every generator joined with
the wall times of its training and sampling jobs, read from their Snakemake benchmark files)
and the report items built from it: the paper-style headline table, the honesty table (where
generated touch must not help), the fidelity table, the guidance x seed heatmap, the sampling
steps x seconds figure, PCA of real vs generated test latents, the pairing-permutation
histogram and the training curves. Pure functions of their arguments.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from tacgen_lib.report import PALETTE, claims
from tacgen_lib.report import format as fmt
from tacgen_lib.report.write import panel_grid

if TYPE_CHECKING:  # pyplot and scipy.stats are imported by the functions that use them:
    # the Findings table reads this module's table helpers without paying for either
    import matplotlib.pyplot as plt

__all__ = [
    "PAPER_CROSS_SEED",
    "PAPER_REAL_TOUCH",
    "cross_seed_interval",
    "delta_with_ci",
    "paper_protocol_note",
    "curve_figure",
    "fidelity_table",
    "generation_summary",
    "guidance_seed_figure",
    "headline_table",
    "honesty_table",
    "pca_figure",
    "protocol_table",
    "permutation_figure",
    "steps_seconds_figure",
    "text_colour",
]


def generation_summary(
    rows: pd.DataFrame, sample_seconds: Mapping[tuple, float], train_seconds: Mapping[tuple, float]
) -> pd.DataFrame:
    """Evaluation rows + ``sample_seconds`` (corpus, seed, sampler, guidance, steps) and
    ``train_seconds`` (corpus, seed) from the benchmark files."""
    out = rows.copy()
    out["sample_seconds"] = [
        sample_seconds.get(
            (r.corpus, int(r.seed), r.sampler, float(r.guidance), int(r.steps)), math.nan
        )
        for r in out.itertuples()
    ]
    out["train_seconds"] = [
        train_seconds.get((r.corpus, int(r.seed)), math.nan) for r in out.itertuples()
    ]
    return out.sort_values("row_id", ignore_index=True)


def cross_seed_interval(values: np.ndarray) -> tuple[float, float, float]:
    """Mean over seeds and its 95 % t-interval (NaN half-width with one seed)."""
    return claims.mean_t_interval(values)


def delta_with_ci(row: Mapping, col: str = "delta") -> tuple[float, float, float]:
    """(Δ, lo, hi) of a summary row: `col` is ``delta`` (against linear V),
    ``delta_vs_nonlinear`` or ``delta_vs_ridge``, each with its CI columns."""
    against = col.removeprefix("delta")
    return tuple(float(row[c]) for c in (col, f"ci_low{against}", f"ci_high{against}"))


def _ci(d: float, lo: float, hi: float) -> str:
    return fmt.with_ci(d, lo, hi, sign=True)


def reference_cell_rows(summary: pd.DataFrame, ref: Mapping) -> pd.DataFrame:
    return summary[
        (summary["sampler"] == ref["sampler"])
        & (summary["steps"] == int(ref["steps"]))
        & np.isclose(summary["guidance"], float(ref["guidance"]))
    ]


def headline_table(summary: pd.DataFrame, ref: Mapping) -> pd.DataFrame:
    """Paper-style table at the reference cell: per corpus x target, the V score beside the
    constant prediction's (majority class / train mean; a V below it is flagged), first-seed
    Delta_gen with its bootstrap CI, the cross-seed mean with its 95 % interval, protocol-matched Delta_real,
    the nonlinear V-only baseline, Delta_gen against that baseline, the ridge V->T generator's
    Delta and Delta_gen against it, and the shuffled control."""
    s = reference_cell_rows(summary, ref)
    out = []
    for (corpus, target), g in s.groupby(["corpus", "target"], sort=True):
        first = int(g["seed"].min())
        by = {k: v for k, v in g.groupby("input")}

        def one(inp: str, col: str = "delta", g1: int = first, by: dict = by) -> str:
            return _ci(*delta_with_ci(by[inp][by[inp]["seed"] == g1].iloc[0], col))

        m, lo, hi = cross_seed_interval(by["t_gen"]["delta"].to_numpy())
        v_score = float(by["t_gen"]["v_score"].iloc[0])
        majority = (
            float(by["t_gen"]["baseline_score"].iloc[0]) if "baseline_score" in g else math.nan
        )
        metric = g["metric"].iloc[0]
        # an accuracy is below the majority rate when its Wilson interval is (claims)
        below = (
            claims.below_majority(v_score, majority, by["t_gen"]["n_test"].iloc[0])
            if metric == "accuracy" and "n_test" in g
            else v_score < majority
        )
        out.append(
            {
                "corpus": corpus,
                "target": target,
                "metric": metric,
                "V score": f"{v_score:.3f}",
                # a V probe worse than the constant prediction is a probe failing: a Δ against
                # it is no evidence (flagged)
                "majority score": majority,
                "V below majority": "yes: Δ is no evidence" if below else "no",
                f"Δ_gen seed {first} [bootstrap CI]": one("t_gen"),
                f"Δ_gen mean over {g['seed'].nunique()} seeds [95% t]": _ci(m, lo, hi),
                "Δ_real (protocol-matched)": one("t_real"),
                "Δ nonlinear V only": one("v_nonlinear"),
                "Δ_gen − nonlinear V": one("t_gen", "delta_vs_nonlinear"),
                "Δ_real − nonlinear V": one("t_real", "delta_vs_nonlinear"),
                "Δ ridge V→T": one("t_ridge"),
                "Δ_gen − ridge V→T": one("t_gen", "delta_vs_ridge"),
                "Δ_gen shuffled V rows": one("t_gen_shuffled"),
            }
        )
    return pd.DataFrame(out)


def honesty_table(summary: pd.DataFrame, ref: Mapping) -> pd.DataFrame:
    """Where generated touch must not help, and whether the pipeline says so.

    Controlled corpus (appearance carries no density): real touch must show Delta > 0 (CI
    lower bound > 0) and generated touch must not (its CI covers 0 or lies below). Null
    corpus: touch carries no label, so neither may help. Every cross-seed row is listed."""
    s = reference_cell_rows(summary, ref)
    out = []
    for r in s[s["input"].isin(["t_real", "t_gen"])].itertuples():
        if r.design == "controlled":
            expect = (
                "Δ > 0 (touch sees density)" if r.input == "t_real" else "no gain (CI ∋ 0 or < 0)"
            )
            ok = r.ci_low > 0 if r.input == "t_real" else r.ci_low <= 0
        elif r.null_corpus:
            expect, ok = "no gain (null corpus)", r.ci_low <= 0
        else:
            continue
        out.append(
            {
                "corpus": r.corpus,
                "target": r.target,
                "seed": r.seed,
                "input": r.input,
                "Δ [CI]": _ci(r.delta, r.ci_low, r.ci_high),
                "expected": expect,
                "as expected": "yes" if ok else "NO",
            }
        )
    return pd.DataFrame(
        out, columns=["corpus", "target", "seed", "input", "Δ [CI]", "expected", "as expected"]
    )


#: The paper's cross-seed result, the protocol table's reference: Delta R^2_gen (mean, 95 %
#: t-interval low, high) over its 5 generator seeds x guidance {0.5, 1, 1.5, 2, 3}, and real
#: touch's Delta R^2, which lies inside that interval.
PAPER_CROSS_SEED: tuple[float, float, float] = (0.589, 0.544, 0.634)
PAPER_REAL_TOUCH = 0.585


def paper_protocol_note() -> str:
    """The protocol table's note stating the paper's result (`PAPER_CROSS_SEED`)."""
    return (
        f"The paper: cross-seed ΔR²_gen {fmt.with_ci(*PAPER_CROSS_SEED, sign=True)} over 5 "
        f"generator seeds × guidance {{0.5, 1, 1.5, 2, 3}}, real touch "
        f"{fmt.signed(PAPER_REAL_TOUCH)} inside the interval."
    )


def protocol_table(summary: pd.DataFrame, ref: Mapping) -> pd.DataFrame:
    """The paper's cross-seed protocol, per corpus x target: Delta_gen averaged over the
    guidance grid (w > 0; w = 0 is unconditional) at the reference sampler and steps, once per
    generator seed, then the mean over seeds with its 95 % t-interval; real touch's Delta beside
    it, and whether it lies inside that interval (the paper's own result: `PAPER_CROSS_SEED`)."""
    s = summary[
        (summary["sampler"] == ref["sampler"])
        & (summary["steps"] == int(ref["steps"]))
        & (summary["guidance"] > 0)
    ]
    out = []
    for (corpus, target), g in s.groupby(["corpus", "target"], sort=True):
        gen = g[g["input"] == "t_gen"]
        per_seed = gen.groupby("seed")["delta"].mean()
        m, lo, hi = cross_seed_interval(per_seed.to_numpy())
        real = float(g.loc[g["input"] == "t_real", "delta"].iloc[0])
        inside = "—" if not math.isfinite(lo) else ("yes" if lo <= real <= hi else "no")
        gs = sorted(float(w) for w in gen["guidance"].unique())
        out.append(
            {
                "corpus": corpus,
                "target": target,
                "metric": g["metric"].iloc[0],
                "seeds × guidance": f"{len(per_seed)} × {len(gs)} ({', '.join(f'{w:g}' for w in gs)})",
                "Δ_gen cross-seed [95% t]": _ci(m, lo, hi),
                "Δ_real": fmt.signed(real),
                "real inside the interval": inside,
                "Δ_gen > 0 (interval above 0)": (
                    "—" if not math.isfinite(lo) else ("yes" if lo > 0 else "no")
                ),
            }
        )
    return pd.DataFrame(out)


#: The fidelity table's name of each generator arm (diffusion: its sampler).
RIDGE_ARMS = {"t_ridge": "ridge V→T (mean)", "t_ridge_residual": "ridge V→T + residual"}


def fidelity_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Per generator seed: each diffusion sampling cell, then the ridge V->T generator's two
    arms (the simplest generator, the bar the diffusion rows must clear): matched vs
    off-diagonal cosine, pairing p, Frechet distances, sampling seconds."""
    cols = ["corpus", "seed", "sampler", "guidance", "steps"]
    diffusion = summary[summary["input"] == "t_gen"].drop_duplicates(cols)
    ridge = summary[summary["input"].isin(list(RIDGE_ARMS))].drop_duplicates(
        ["corpus", "seed", "input"]
    )
    ridge = ridge.assign(
        generator=ridge["input"].map(RIDGE_ARMS),
        sampler="—",
        sample_seconds=math.nan,
        order=1,
    )
    s = pd.concat(
        [diffusion.assign(generator="diffusion", order=0), ridge], ignore_index=True
    ).sort_values(["corpus", "seed", "order", "generator", "sampler", "guidance", "steps"])
    return pd.DataFrame(
        {
            "generator": s["generator"].to_numpy(),
            **{c: s[c].to_numpy() for c in ("corpus", "seed", "sampler")},
            # the ridge generator has no guidance or sampling steps
            "guidance": [
                g if o == 0 else "—" for g, o in zip(s["guidance"], s["order"], strict=True)
            ],
            "steps": [st if o == 0 else "—" for st, o in zip(s["steps"], s["order"], strict=True)],
            "cos matched": s["cos_matched"].map("{:.3f}".format).to_numpy(),
            "cos off-diagonal": s["cos_offdiag"].map("{:.3f}".format).to_numpy(),
            "pairing p": s["pairing_p"].map("{:.3f}".format).to_numpy(),
            "Fréchet gen–real": s["frechet"].map("{:.2f}".format).to_numpy(),
            "Fréchet real train–test": s["frechet_real_ref"].map("{:.2f}".format).to_numpy(),
            "sample s": ["—" if math.isnan(x) else f"{x:.1f}" for x in s["sample_seconds"]],
        }
    )


def _panels(n: int, ncols: int = 3, panel_size: tuple[float, float] = (3.1, 3.0)):
    import matplotlib.pyplot as plt

    nrows, ncols, figsize = panel_grid(n, panel_size, max_cols=ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=figsize, squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def text_colour(rgba: Sequence[float]) -> str:
    """Black or white, whichever reads better on a cell of colour `rgba`: white when the
    cell's relative luminance (WCAG 2.x: 0.2126 R + 0.7152 G + 0.0722 B of the linearised
    sRGB channels) is below 0.179, the point where both give the same contrast ratio."""

    def linear(c: float) -> float:
        return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4

    r, g, b = (linear(float(c)) for c in rgba[:3])
    return "white" if 0.2126 * r + 0.7152 * g + 0.0722 * b < 0.179 else "black"


def guidance_seed_figure(summary: pd.DataFrame, sampler: str, steps: int) -> plt.Figure:
    """Heatmap of Delta_gen per guidance w (rows) x seed (columns), one panel per target,
    each cell annotated with Delta and its bootstrap CI."""
    s = summary[
        (summary["input"] == "t_gen")
        & (summary["sampler"] == sampler)
        & (summary["steps"] == int(steps))
    ]
    groups = list(s.groupby(["corpus", "target"], sort=True))
    fig, axes = _panels(len(groups), panel_size=(3.0, 3.0))
    # one colour scale for every panel, symmetric about 0, with its colour bar
    finite = s["delta"].to_numpy(float)
    finite = finite[np.isfinite(finite)]
    lim = max(float(np.abs(finite).max()) if finite.size else 0.0, 1e-3)
    image = None
    for ax, ((corpus, target), g) in zip(axes, groups, strict=False):
        ws, seeds = sorted(g["guidance"].unique()), sorted(g["seed"].unique())
        grid = np.full((len(ws), len(seeds)), np.nan)
        for r in g.itertuples():
            grid[ws.index(r.guidance), seeds.index(r.seed)] = r.delta
        image = ax.imshow(grid, cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto")
        for r in g.itertuples():
            i, j = ws.index(r.guidance), seeds.index(r.seed)
            ax.text(
                j,
                i,
                f"{fmt.signed(r.delta)}\n[{fmt.signed(r.ci_low, 2)}, {fmt.signed(r.ci_high, 2)}]",
                ha="center",
                va="center",
                fontsize=8,
                color=text_colour(image.cmap(image.norm(r.delta))),
            )
        ax.set_xticks(range(len(seeds)), [str(x) for x in seeds])
        ax.set_yticks(range(len(ws)), [f"{w:g}" for w in ws])
        ax.set_xlabel("generator seed")
        ax.set_ylabel("guidance w")
        ax.set_title(f"{corpus}: {target}", fontsize=9)
    fig.suptitle(f"Δ_gen = score(V+T_gen) − score(V), {sampler} {steps} steps", fontsize=10)
    fig.tight_layout()
    if image is not None:
        fig.colorbar(image, ax=list(axes), shrink=0.8, label="Δ_gen (one scale for all panels)")
    return fig


def steps_seconds_figure(summary: pd.DataFrame) -> plt.Figure:
    """What accuracy costs in time: sampling seconds (benchmark) against Delta_gen (mean over
    seeds and guidance, per target) and against the Frechet distance, points labelled by steps."""
    import matplotlib.pyplot as plt

    s = summary[summary["input"] == "t_gen"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.5, 4))
    for (corpus, target, sampler), g in s.groupby(["corpus", "target", "sampler"], sort=True):
        agg = (
            g.groupby("steps")
            .agg(sec=("sample_seconds", "mean"), d=("delta", "mean"), fd=("frechet", "mean"))
            .reset_index()
        )
        line = ax1.plot(agg["sec"], agg["d"], "o-", label=f"{corpus}:{target} ({sampler})")[0]
        for r in agg.itertuples():
            ax1.annotate(
                str(r.steps), (r.sec, r.d), fontsize=8, xytext=(3, 3), textcoords="offset points"
            )
        ax2.plot(agg["sec"], agg["fd"], "o-", color=line.get_color())
        for r in agg.itertuples():
            ax2.annotate(
                str(r.steps), (r.sec, r.fd), fontsize=8, xytext=(3, 3), textcoords="offset points"
            )
    ax1.axhline(0, color="grey", lw=0.8)
    ax1.set_xlabel("sampling job seconds (benchmark file)")
    ax1.set_ylabel("Δ_gen (mean over seeds and w)")
    ax2.set_xlabel("sampling job seconds (benchmark file)")
    ax2.set_ylabel("Fréchet distance, generated vs real test")
    ax1.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _ellipse(ax: plt.Axes, pts: np.ndarray, color: str) -> None:
    from matplotlib.patches import Ellipse

    cov = np.cov(pts, rowvar=False)
    w, v = np.linalg.eigh(cov)
    w = np.clip(w, 0, None)
    angle = math.degrees(math.atan2(v[1, 1], v[0, 1]))
    ax.add_patch(
        Ellipse(
            pts.mean(0),
            4 * math.sqrt(w[1]),
            4 * math.sqrt(w[0]),
            angle=angle,
            fill=False,
            color=color,
            lw=1.5,
        )
    )


def pca_figure(real: np.ndarray, gen: np.ndarray, *, title: str) -> plt.Figure:
    """Real and generated test latents on the first two principal components of the real
    ones, each with its 2-sd covariance ellipse."""
    import matplotlib.pyplot as plt

    real, gen = np.asarray(real, np.float64), np.asarray(gen, np.float64)
    mu = real.mean(0)
    _, _, vt = np.linalg.svd(real - mu, full_matrices=False)
    pr, pg = (real - mu) @ vt[:2].T, (gen - mu) @ vt[:2].T
    fig, ax = plt.subplots(figsize=(5, 4.5))
    ax.scatter(pr[:, 0], pr[:, 1], s=8, alpha=0.5, label="real T", color=PALETTE["blue"])
    ax.scatter(pg[:, 0], pg[:, 1], s=8, alpha=0.5, label="generated T", color=PALETTE["orange"])
    _ellipse(ax, pr, PALETTE["blue"])
    _ellipse(ax, pg, PALETTE["orange"])
    ax.set_xlabel("PC 1 (real)")
    ax.set_ylabel("PC 2 (real)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def permutation_figure(perms: pd.DataFrame, ref: Mapping) -> plt.Figure:
    """Pairing-permutation histograms (re-paired matched cosine) with the observed value."""
    p = perms[
        (perms["sampler"] == ref["sampler"])
        & (perms["steps"] == int(ref["steps"]))
        & np.isclose(perms["guidance"], float(ref["guidance"]))
    ]
    p = p[p["seed"] == p["seed"].min()] if len(p) else p
    groups = list(p.groupby(["corpus", "target"], sort=True))
    fig, axes = _panels(max(len(groups), 1))
    for ax, ((corpus, target), g) in zip(axes, groups, strict=False):
        obs = float(g["observed"].iloc[0])
        ax.hist(g["statistic"], bins=30, color="lightgrey", edgecolor="grey")
        ax.axvline(obs, color=PALETTE["vermillion"], label=f"observed {obs:.3f}")
        pval = (1 + np.sum(g["statistic"] >= obs)) / (1 + len(g))
        ax.set_title(f"{corpus}: {target} (p = {pval:.3f})", fontsize=9)
        ax.set_xlabel("mean matched cosine, re-paired")
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def curve_figure(curves: pd.DataFrame) -> plt.Figure:
    """Train and validation denoising loss per generator (corpus x seed); a panel whose
    validation loss still falls at its last step says so in its title (`claims.still_falling`)."""
    groups = list(curves.groupby("corpus", sort=True))
    fig, axes = _panels(max(len(groups), 1))
    for ax, (corpus, g) in zip(axes, groups, strict=False):
        falling = []
        for seed, c in g.groupby("seed"):
            line = ax.plot(c["step"], c["train_loss"], "-", label=f"seed {seed} train")[0]
            ax.plot(
                c["step"], c["val_loss"], "--", color=line.get_color(), label=f"seed {seed} val"
            )
            if claims.still_falling(c["step"], c["val_loss"]):
                falling.append(str(seed))
        note = f"\nval loss still falling at the end (seed {', '.join(falling)})" if falling else ""
        ax.set_title(f"{corpus}{note}", fontsize=9, color="#b22222" if falling else "black")
        ax.set_xlabel("optimiser step")
        ax.set_ylabel("denoising loss")
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
