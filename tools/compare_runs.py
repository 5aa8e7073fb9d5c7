"""Compare two runs of one config: their conclusions first, then their edges.

Two runs of the same config on other CPU classes, kernels or devices write different bytes
(docs/tests.md); what must agree is what the findings page decides. This prints

1. the decisions (``results/report/findings/decisions.parquet`` of each run,
   `tacgen_lib.report.decisions.compare_decisions`): how many agree, and every one that
   differs or that one run states alone, with both values and intervals;
2. the edges (`tacgen_lib.io.compare.compare_runs`): per stage, how many hashed files are
   identical, within the stage's tolerance on the largest relative difference, or beyond it,
   and the largest difference; then every edge beyond its tolerance.

    .venv/bin/python tools/compare_runs.py RUN_A/results RUN_B/results [--tolerance stage=x ...]
        [--csv DIR]

Tolerances (`tacgen_lib.io.compare.STAGE_TOLERANCES`, overridden by --tolerance) bound the
stages no training touches; a stage downstream of a training loop (a backbone's pretraining,
the heads, the generators, the policy) carries a last-bit difference into its weights and is
reported, not bounded: its conclusions are compared by the decisions. Exit status 1 when a
decision differs, when an edge of a bounded stage is not within its tolerance, or when the
runs do not hold the same edges with the same keys; 0 otherwise.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import pandas as pd  # noqa: E402

from tacgen_lib.io import edges  # noqa: E402
from tacgen_lib.io.compare import STAGE_TOLERANCES, compare_runs  # noqa: E402
from tacgen_lib.report.decisions import DECISIONS_EDGE, compare_decisions  # noqa: E402


def _tolerances(items: list[str]) -> dict[str, float]:
    out = dict(STAGE_TOLERANCES)
    for item in items:
        stage, _, value = item.partition("=")
        if not stage or not value:
            raise SystemExit(f"compare_runs: --tolerance wants stage=value, got {item!r}")
        out[stage] = float(value)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path, help="the first run's results/ folder")
    ap.add_argument("b", type=Path, help="the second run's results/ folder")
    ap.add_argument("--tolerance", action="append", default=[], metavar="STAGE=X")
    ap.add_argument("--csv", type=Path, default=None, help="also write both tables here")
    args = ap.parse_args(argv)
    pd.set_option("display.width", 200)
    pd.set_option("display.max_colwidth", 70)
    failed = False

    paths = [args.a / DECISIONS_EDGE, args.b / DECISIONS_EDGE]
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        print(f"decisions: not produced by {', '.join(missing)} (rule findings)")
        decisions = None
    else:
        decisions = compare_decisions(*(edges.read(p).frame for p in paths))
        counts = decisions["status"].value_counts()
        print(
            f"decisions: {len(decisions)} compared, {counts.get('same', 0)} the same, "
            f"{counts.get('differs', 0)} differ, {counts.get('only in a', 0)} only in a, "
            f"{counts.get('only in b', 0)} only in b"
        )
        odd = decisions[decisions["status"] != "same"]
        if len(odd):
            failed = True
            print(odd.to_string(index=False))

    tolerances = _tolerances(args.tolerance)
    table = compare_runs(args.a, args.b, tolerances, default_tolerance=math.inf)
    print(f"\nedges: {table['edge'].nunique()} hashed files")
    per_stage = table.groupby("stage", sort=True).agg(
        files=("edge", "nunique"),
        identical=("status", lambda s: int((s == "identical").sum())),
        within=("status", lambda s: int((s == "within").sum())),
        beyond=("status", lambda s: int((s == "beyond").sum())),
        other=(
            "status",
            lambda s: int((~s.isin(["identical", "within", "beyond"])).sum()),
        ),
        max_rel=("max_rel", "max"),
    )
    per_stage["tolerance"] = [tolerances.get(s, math.inf) for s in per_stage.index]
    print(per_stage.to_string(float_format=lambda x: f"{x:.3g}"))
    bounded = table["tolerance"].map(math.isfinite)
    structure = table["status"].isin(["keys differ", "only in a", "only in b"])
    off = table[structure | (bounded & ~table["status"].isin(["identical", "within"]))]
    if len(off):
        failed = True
        print("\nedges beyond their stage's tolerance, or present or keyed in one run only:")
        print(off.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    if args.csv:
        args.csv.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.csv / "edges.csv", index=False)
        if decisions is not None:
            decisions.to_csv(args.csv / "decisions.csv", index=False)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
