"""The report page *Pixel generators* (`tacgen_lib.generate.pixel`): the paper's architecture
table measured (reconstruction and utility of Pix2Pix, the pixel DDPM and the latent generator
on the same test rows, with their controls), the contrast calibration before and after, the
generated-fraction curve of alignment retraining with its shuffled control, reconstruction
against utility, and filmstrips of generated frames; every sentence from the numbers."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from tacgen_lib.generate.pixel.utility import REAL_LOWRES
from tacgen_lib.report import format as fmt
from tacgen_lib.report.write import FIGURE_DPI, MAX_FIGURE_PX, panel_grid

__all__ = [
    "architecture_sentences",
    "architecture_table",
    "calibration_table",
    "curve_figure",
    "curve_sentences",
    "filmstrip_figure",
    "scatter_figure",
    "utility_view",
]

#: What each arm is, for a reader.
ARM_LABELS = {
    "pix2pix": "Pix2Pix",
    "ddpm": "pixel DDPM",
    REAL_LOWRES: "real frames at the generators' size (reference)",
    "latent": "latent DDPM (Generation page)",
}


def arm_label(arm: str) -> str:
    """'Pix2Pix', 'pixel DDPM w=1, 10 steps', '… calibrated'."""
    base = arm.removesuffix("_cal")
    if base.startswith("ddpm_"):
        w, s = base.removeprefix("ddpm_w").split("_s")
        text = f"pixel DDPM w={w}, {s} steps"
    else:
        text = ARM_LABELS.get(base, base)
    return text + (", calibrated" if arm.endswith("_cal") else "")


def utility_view(rows: pd.DataFrame, latent: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per corpus x seed x target x arm: V + T_arm against V (and its shuffled-pairing
    control, nonlinear V and ridge V->T), with the latent generator's reference-cell row of
    the same corpus x target x seed where given (`latent`: the Generation page's evaluation,
    sampler/guidance/steps of its reference cell already selected)."""
    gen = rows[rows["input"] == "t_gen"].copy()
    shuf = rows[rows["input"] == "t_gen_shuffled"].set_index(["corpus", "seed", "target", "arm"])
    key = list(zip(gen["corpus"], gen["seed"], gen["target"], gen["arm"], strict=True))
    gen["shuffled_delta"] = [shuf.loc[k, "delta"] for k in key]
    gen["shuffled_ci_high"] = [shuf.loc[k, "ci_high"] for k in key]
    parts = [gen]
    extra = rows[rows["input"].isin(["t_real", "t_ridge"])].drop_duplicates(
        ["corpus", "seed", "target", "input"]
    )
    extra = extra.assign(arm=extra["input"].map({"t_real": "t_real", "t_ridge": "t_ridge"}))
    # the real-touch rows carry their cell's generated fidelity in the evaluation: not theirs
    real = extra["arm"] == "t_real"
    for col in ("cos_matched", "cos_offdiag", "frechet", "pairing_p"):
        if col in extra:
            extra.loc[real, col] = np.nan
    parts.append(extra)
    if latent is not None and len(latent):
        lat = latent[latent["input"].isin(["t_gen", "t_gen_shuffled"])]
        lg = lat[lat["input"] == "t_gen"].copy()
        ls = lat[lat["input"] == "t_gen_shuffled"].set_index(["corpus", "seed", "target"])
        k2 = list(zip(lg["corpus"], lg["seed"], lg["target"], strict=True))
        lg["shuffled_delta"] = [ls.loc[k, "delta"] if k in ls.index else np.nan for k in k2]
        lg["shuffled_ci_high"] = [ls.loc[k, "ci_high"] if k in ls.index else np.nan for k in k2]
        lg["arm"] = "latent"
        parts.append(lg[lg["corpus"].isin(set(gen["corpus"]))])
    return pd.concat(parts, ignore_index=True)


_ARM_ORDER = ("t_real", REAL_LOWRES, "pix2pix", "ddpm", "latent", "t_ridge")


def _arm_rank(arm: str) -> tuple[int, int, str]:
    base = arm.removesuffix("_cal")
    first = base if base in _ARM_ORDER else base.split("_")[0]
    return (
        _ARM_ORDER.index(first) if first in _ARM_ORDER else len(_ARM_ORDER),
        arm.endswith("_cal"),
        arm,
    )


def _label_any(arm: str) -> str:
    return {"t_real": "real touch (full size)", "t_ridge": "ridge V→T (simplest generator)"}.get(
        arm, arm_label(arm)
    )


def architecture_table(view: pd.DataFrame, reconstruction: pd.DataFrame) -> pd.DataFrame:
    """Reconstruction and utility per arm, one row per corpus x target x arm (first seed)."""
    seed = view["seed"].min()
    v = view[view["seed"] == seed]
    rec = reconstruction[reconstruction["seed"] == seed].set_index(["corpus", "arm"])
    out = []
    for (corpus, target), g in v.groupby(["corpus", "target"], sort=True):
        for x in sorted(g.itertuples(), key=lambda r: _arm_rank(r.arm)):
            has_rec = (corpus, x.arm) in rec.index
            r = rec.loc[(corpus, x.arm)] if has_rec else None
            out.append(
                {
                    "corpus": corpus,
                    "target": f"{target} ({x.metric})",
                    "arm": _label_any(x.arm),
                    "pixel-L2 [95% CI]": fmt.with_ci(r.pixel_l2, r.pixel_l2_low, r.pixel_l2_high)
                    if has_rec
                    else "",
                    "SSIM [95% CI]": fmt.with_ci(r.ssim, r.ssim_low, r.ssim_high)
                    if has_rec
                    else "",
                    "ViT cos matched / off-diagonal": (
                        f"{fmt.number(x.cos_matched)} / {fmt.number(x.cos_offdiag)}"
                        if not fmt.is_missing(getattr(x, "cos_matched", np.nan))
                        else ""
                    ),
                    "V": fmt.number(x.v_score),
                    "Δ vs V [95% CI]": fmt.with_ci(x.delta, x.ci_low, x.ci_high, sign=True),
                    "Δ vs nonlinear V [95% CI]": fmt.with_ci(
                        x.delta_vs_nonlinear,
                        x.ci_low_vs_nonlinear,
                        x.ci_high_vs_nonlinear,
                        sign=True,
                    ),
                    "control: shuffled pairing Δ": fmt.signed(getattr(x, "shuffled_delta", np.nan)),
                    "seconds (train + sample)": _seconds(getattr(x, "seconds", np.nan)),
                }
            )
    return pd.DataFrame(out)


def _seconds(x: float) -> str:
    return "" if fmt.is_missing(x) else f"{x:.0f}"


def utility_positive(x) -> bool:
    """Utility-positive: Δ vs V with its CI above 0 and above the shuffled control's interval."""
    return bool(
        x.ci_low > 0 and (fmt.is_missing(x.shuffled_ci_high) or x.ci_low > x.shuffled_ci_high)
    )


def architecture_sentences(view: pd.DataFrame, reconstruction: pd.DataFrame) -> list[str]:
    """Per corpus x target: which generators are utility-positive, the best by reconstruction
    (SSIM) and by utility (Δ), and whether the two axes rank the generators alike."""
    seed = view["seed"].min()
    v = view[(view["seed"] == seed)]
    rec = reconstruction[(reconstruction["seed"] == seed)].set_index(["corpus", "arm"])
    out = []
    for (corpus, target), g in v.groupby(["corpus", "target"], sort=True):
        gens = g[~g["arm"].isin(["t_real", "t_ridge", REAL_LOWRES])]
        if gens.empty:
            continue
        positive = [_label_any(x.arm) for x in gens.itertuples() if utility_positive(x)]
        real = g[g["arm"] == "t_real"]
        real_text = (
            f"real touch Δ {fmt.with_ci(*real[['delta', 'ci_low', 'ci_high']].iloc[0], sign=True)}"
            if len(real)
            else "no real-touch row"
        )
        lowres = g[g["arm"] == REAL_LOWRES]
        if len(lowres):
            real_text += (
                f", real frames at the generators' size "
                f"{fmt.with_ci(*lowres[['delta', 'ci_low', 'ci_high']].iloc[0], sign=True)}"
            )
        sentence = f"{corpus}, {target}: {real_text}. "
        sentence += (
            "Utility-positive (Δ CI above 0 and above its shuffled control): "
            + ", ".join(positive)
            + "."
            if positive
            else "No generator is utility-positive (none has a Δ CI above 0 and above its "
            "shuffled control)."
        )
        pixel = [
            x
            for x in gens.itertuples()
            if (corpus, x.arm) in rec.index and not x.arm.endswith("_cal")
        ]
        if len(pixel) >= 2:
            by_rec = max(pixel, key=lambda x: rec.loc[(corpus, x.arm), "ssim"])
            by_use = max(pixel, key=lambda x: x.delta)
            others = [x for x in pixel if x.arm != by_use.arm]
            apart = all(by_use.ci_low > x.ci_high for x in others)
            sentence += f" Best reconstruction (SSIM): {_label_any(by_rec.arm)}. "
            if not apart:
                sentence += (
                    f"By utility the generators cannot be told apart: the best point estimate "
                    f"({_label_any(by_use.arm)}, Δ {fmt.signed(by_use.delta)}) has an interval "
                    "overlapping another generator's."
                )
            elif by_rec.arm == by_use.arm:
                sentence += (
                    "It is also the most useful, its Δ interval above the others': the axes agree."
                )
            else:
                sentence += (
                    f"The most useful is {_label_any(by_use.arm)} (Δ interval above the others'): "
                    "reconstruction and utility rank the generators differently."
                )
        out.append(sentence)
    return out


def calibration_table(reconstruction: pd.DataFrame, view: pd.DataFrame) -> pd.DataFrame:
    """Per arm before and after the train-fitted contrast gain: the gain, std and high-pass
    ratios of generated to real test frames, the share of values clipped into the frame's
    range, and the utility Δ per target."""
    seed = reconstruction["seed"].min()
    rec = reconstruction[reconstruction["seed"] == seed]
    v = view[view["seed"] == seed].set_index(["corpus", "arm", "target"])
    targets = sorted(set(view["target"]))
    out = []
    for x in sorted(rec.itertuples(), key=lambda r: (r.corpus, _arm_rank(r.arm))):
        row = {
            "corpus": x.corpus,
            "arm": arm_label(x.arm),
            "gain (train rows)": fmt.number(x.gain) if x.calibrated else "1 (none)",
            "std ratio gen/real": fmt.number(x.std_ratio),
            "high-pass ratio gen/real": fmt.number(x.highpass_ratio),
            "share clipped to 0–255": fmt.number(x.clipped, 4),
        }
        for t in targets:
            k = (x.corpus, x.arm, t)
            row[f"{t}: Δ vs V [95% CI]"] = (
                fmt.with_ci(v.loc[k, "delta"], v.loc[k, "ci_low"], v.loc[k, "ci_high"], sign=True)
                if k in v.index
                else ""
            )
        out.append(row)
    return pd.DataFrame(out)


def curve_sentences(points: pd.DataFrame) -> list[str]:
    """Per corpus x target: Δ at the smallest and largest generated fraction, whether Δ falls
    monotonically with p (the paper's curve rises for force), and the shuffled control at the
    largest p."""
    out = []
    seed = points["seed"].min()
    p = points[points["seed"] == seed]
    for (corpus, target), g in p.groupby(["corpus", "target"], sort=True):
        gen = g[(g["pairing"] == "generated")].sort_values("fraction")
        shuf = g[(g["pairing"] == "shuffled")].sort_values("fraction")
        if gen.empty:
            continue
        lo, hi = gen.iloc[0], gen.iloc[-1]
        d = gen["delta"].to_numpy()
        if len(d) > 2:
            trend = (
                "the point estimates rise monotonically with p"
                if np.all(np.diff(d) > 0)
                else "the point estimates fall monotonically with p"
                if np.all(np.diff(d) < 0)
                else "the point estimates are not monotone in p"
            )
        else:
            move = "rises" if d[-1] > d[0] else "falls" if d[-1] < d[0] else "stays"
            trend = f"the point estimate {move} from p = {lo.fraction:g} to p = {hi.fraction:g}"
        ends = "apart" if lo.ci_low > hi.ci_high or hi.ci_low > lo.ci_high else "overlapping"
        text = (
            f"{corpus}, {target}: Δ (V+T − V on real held-out touch) "
            f"{fmt.with_ci(lo.delta, lo.ci_low, lo.ci_high, sign=True)} at p = {lo.fraction:g}, "
            f"{fmt.with_ci(hi.delta, hi.ci_low, hi.ci_high, sign=True)} at p = {hi.fraction:g} "
            f"(intervals {ends}); {trend}."
        )
        s_hi = shuf[shuf["fraction"] == hi.fraction]
        if len(s_hi):
            s = s_hi.iloc[0]
            apart = hi.ci_low > s.ci_high or hi.ci_high < s.ci_low
            text += (
                f" The shuffled generator at p = {hi.fraction:g}: "
                f"{fmt.with_ci(s.delta, s.ci_low, s.ci_high, sign=True)}, "
                + (
                    "its interval apart from the generated one's."
                    if apart
                    else "its interval overlapping the generated one's."
                )
            )
        out.append(text)
    return out


def curve_figure(points: pd.DataFrame) -> plt.Figure:
    """Δ against the generated fraction p per corpus x target: the generated pairing with its
    95 % CI band, the shuffled generator dashed (the control), 0 dotted."""
    seed = points["seed"].min()
    p = points[points["seed"] == seed]
    panels = sorted(set(zip(p["corpus"], p["target"], strict=True)))
    nrows, ncols, size = panel_grid(max(len(panels), 1), (4.5, 3.2), max_cols=2)
    fig, axes = plt.subplots(nrows, ncols, figsize=size, squeeze=False)
    for ax, (corpus, target) in zip(axes.ravel(), panels, strict=False):
        g = p[(p["corpus"] == corpus) & (p["target"] == target)]
        p0 = g[g["fraction"] == 0]
        for pairing, style, color in (("generated", "-o", "tab:blue"), ("shuffled", "--s", "grey")):
            h = pd.concat([p0, g[(g["pairing"] == pairing) & (g["fraction"] > 0)]])
            h = h.drop_duplicates("fraction").sort_values("fraction")
            ax.plot(h["fraction"], h["delta"], style, color=color, ms=4, label=pairing)
            ax.fill_between(h["fraction"], h["ci_low"], h["ci_high"], color=color, alpha=0.15)
        ax.axhline(0.0, color="k", lw=0.7, ls=":")
        ax.set_title(f"{corpus}: {target} ({g['metric'].iloc[0]})", fontsize=9)
        ax.set_xlabel("generated fraction p of the heads' rows")
        ax.set_ylabel("Δ on real touch (V+T − V)")
        ax.legend(fontsize=8, frameon=False)
    for ax in axes.ravel()[len(panels) :]:
        ax.axis("off")
    fig.tight_layout()
    return fig


def scatter_figure(view: pd.DataFrame, reconstruction: pd.DataFrame) -> plt.Figure:
    """Reconstruction (SSIM, x) against utility (Δ vs V, y, with its CI) per arm, one panel
    per corpus x target: the paper's two axes."""
    seed = view["seed"].min()
    v = view[view["seed"] == seed]
    rec = reconstruction[reconstruction["seed"] == seed].set_index(["corpus", "arm"])
    panels = sorted(set(zip(v["corpus"], v["target"], strict=True)))
    nrows, ncols, size = panel_grid(max(len(panels), 1), (4.5, 3.0), max_cols=2)
    height = min(size[1] + 1.0, MAX_FIGURE_PX[1] / FIGURE_DPI)  # + a row for the legend
    fig, axes = plt.subplots(nrows, ncols, figsize=(size[0], height), squeeze=False)
    for ax, (corpus, target) in zip(axes.ravel(), panels, strict=False):
        g = v[(v["corpus"] == corpus) & (v["target"] == target)]
        arms = sorted(
            (x for x in g.itertuples() if (corpus, x.arm) in rec.index),
            key=lambda r: _arm_rank(r.arm),
        )
        for k, x in enumerate(arms):
            ax.errorbar(
                rec.loc[(corpus, x.arm), "ssim"],
                x.delta,
                yerr=[[x.delta - x.ci_low], [x.ci_high - x.delta]],
                fmt="s" if x.arm.endswith("_cal") else "o",
                ms=5,
                color=plt.cm.tab10(k % 10),
                label=arm_label(x.arm),
            )
        real = g[g["arm"] == "t_real"]
        if len(real):
            ax.axhline(
                real["delta"].iloc[0], color="tab:green", lw=0.8, ls="--", label="real touch Δ"
            )
        ax.axhline(0.0, color="k", lw=0.7, ls=":")
        ax.set_xlabel("SSIM to the real frame (reconstruction)")
        ax.set_ylabel("Δ vs V (utility)")
        ax.set_title(f"{corpus}: {target}", fontsize=9)
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    for ax in axes.ravel()[len(panels) :]:
        ax.axis("off")
    fig.legend(handles, labels, fontsize=8, frameon=False, loc="lower center", ncol=3)
    fig.tight_layout(rect=(0, 1.0 / height, 1, 1))
    return fig


def filmstrip_figure(
    rgb: np.ndarray,
    real: np.ndarray,
    gen: np.ndarray,
    *,
    sample_ids: list[str],
    title: str,
) -> plt.Figure:
    """Rows of test samples; columns RGB, real tactile, generated, generated − real, and the
    high-pass (Laplacian) maps of real and generated. Tactile columns share one scale: the
    clip128 frame's deviation from the background, and one symmetric scale for the differences
    and the high-pass maps."""
    from scipy.ndimage import laplace

    n = len(sample_ids)
    fig, axes = plt.subplots(n, 6, figsize=(9.2, 1.45 * n + 0.7), squeeze=False)
    dev = lambda x: np.abs(x.astype(np.float32) - 128.0).mean(axis=-1)  # noqa: E731
    lap = lambda x: laplace(x.astype(np.float64).mean(axis=-1), mode="mirror")  # noqa: E731
    vmax = max(float(dev(real).max()), float(dev(gen).max()), 1.0)
    diffs = gen.astype(np.float32).mean(-1) - real.astype(np.float32).mean(-1)
    dmax = max(float(np.abs(diffs).max()), 1.0)
    hp = [lap(f) for f in np.concatenate([real, gen])]
    hmax = max(max(float(np.abs(h).max()) for h in hp), 1.0)
    heads = [
        "RGB",
        "real tactile",
        "generated",
        "generated − real",
        "high-pass real",
        "high-pass gen.",
    ]
    for i in range(n):
        row = axes[i]
        row[0].imshow(rgb[i])
        row[1].imshow(dev(real[i]), cmap="magma", vmin=0, vmax=vmax)
        row[2].imshow(dev(gen[i]), cmap="magma", vmin=0, vmax=vmax)
        row[3].imshow(diffs[i], cmap="coolwarm", vmin=-dmax, vmax=dmax)
        row[4].imshow(lap(real[i]), cmap="coolwarm", vmin=-hmax, vmax=hmax)
        row[5].imshow(lap(gen[i]), cmap="coolwarm", vmin=-hmax, vmax=hmax)
        row[0].set_ylabel(sample_ids[i], fontsize=8)
        for j, ax in enumerate(row):
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(heads[j], fontsize=8)
    fig.suptitle(
        f"{title} — tactile columns: |frame − background| on one scale (0–{vmax:.0f}); "
        "differences and high-pass on symmetric scales",
        fontsize=8,
    )
    fig.tight_layout()
    return fig
