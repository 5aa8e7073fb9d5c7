"""Which V vs V+T comparisons a probe family makes (inputs × tactile variants × fusions ×
alignment seeds), which of them run controls, and each comparison's row key."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from tacgen_lib.probes.fusion import FUSIONS

# --------------------------------------------------------------------------- plan


@dataclass(frozen=True)
class ComparisonSpec:
    """One V vs V+T comparison of a family: its input, tactile variant, fusion, seed."""

    input: str  # "raw" | "aligned"
    t_variant: str
    fusion: str
    align_seed: int | None
    controls: bool
    skip_reason: str | None = None


def plan_comparisons(
    fusions: Sequence[str],
    *,
    heads_variant: str,
    variants: Sequence[str],
    align_seeds: Sequence[int],
    dim_v_raw: int,
    dim_t_raw: int,
    control_align_seeds: int | None = None,
) -> list[ComparisonSpec]:
    """Every comparison of a family, in a fixed order (raw, tactile ablation, aligned).

    Controls run on ``concat`` of raw (heads' variant) and of aligned (every alignment seed,
    or only the first `control_align_seeds` in sorted order); when ``concat`` is not among the
    aligned fusions, on the first configured fusion instead.
    Same-dimension fusions on raw features of unequal dimension are planned as skipped rows.
    """
    unknown = [f for f in fusions if f not in FUSIONS]
    if unknown:
        raise ValueError(f"unknown fusion(s) {unknown}; choose from {sorted(FUSIONS)}")
    fusions = list(dict.fromkeys(fusions))
    raw_fusions = ["concat"] + [f for f in fusions if f != "concat"]
    control_aligned = "concat" if "concat" in fusions else fusions[0]
    plan = []
    for f in raw_fusions:
        reason = None
        if FUSIONS[f].same_dim and dim_v_raw != dim_t_raw:
            reason = (
                f"fusion {f!r} needs V and T of equal dimension; raw V has {dim_v_raw} and "
                f"raw T {dim_t_raw} (use the aligned input or concat)"
            )
        plan.append(ComparisonSpec("raw", heads_variant, f, None, f == "concat", reason))
    for v in variants:
        if v != heads_variant:
            plan.append(ComparisonSpec("raw", v, "concat", None, False))
    seeds = sorted(align_seeds)
    with_controls = set(seeds if control_align_seeds is None else seeds[:control_align_seeds])
    for s in seeds:
        for f in fusions:
            ctl = f == control_aligned and s in with_controls
            plan.append(ComparisonSpec("aligned", heads_variant, f, int(s), ctl))
    return plan


def row_id(
    family: str,
    spec: ComparisonSpec,
    probe_seed: int,
    control: str = "none",
    protocol: str = "raw",
) -> str:
    """The key of a result row (unique within a run); ``raw`` rows keep their older key."""
    a = "-" if spec.align_seed is None else str(spec.align_seed)
    p = "" if protocol == "raw" else f"p~{protocol}|"
    return (
        f"{family}|{spec.input}|t~{spec.t_variant}|{spec.fusion}|a~{a}|s~{probe_seed}|{p}{control}"
    )


def headline_plan(
    plan: Sequence[ComparisonSpec], heads_variant: str, *, controls: bool
) -> list[ComparisonSpec]:
    """The headline comparisons of a plan: ``concat`` with the heads' tactile variant (raw,
    and aligned per alignment seed), with controls only if `controls`."""
    return [
        replace(s, controls=s.controls and controls)
        for s in plan
        if s.fusion == "concat" and s.t_variant == heads_variant and s.skip_reason is None
    ]
