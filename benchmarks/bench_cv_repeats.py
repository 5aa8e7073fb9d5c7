"""How much a generator verdict hinges on the CV's fold draw, per number of repeated draws.

On a finished run, for one corpus, target and sampling cell of the first generator seed: the
V and V + T_gen probes of the generator's evaluation (`target_specs`, `fit_probe`) are fitted
under `--draws` different fold draws (probe seeds 0, 1, ... for the folds; the bootstrap drawn
with seed 0 every time, `--bootstrap` resamples), with the CV averaging `cv_repeats` draws of
the folds, for each value of `--repeats`. Prints, per value: the range and standard deviation
of Delta_gen over the fold draws, how many of them have a CI above 0, and the regularisers
chosen. What config ``generate.cv_repeats`` buys, and its price in fits.

    .venv/bin/python benchmarks/bench_cv_repeats.py [--results results] [--corpus sim_paired]
        [--target hardness] [--cell ddim/1/25] [--repeats 1,5,10,20] [--draws 20]
        [--configfile config/config.yaml]

`--configfile` names the run's config (merged over config/config.yaml as Snakemake merges
its own `--configfile`).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from machine import TINY_CONFIG, parse_args, run_config
from threadpoolctl import threadpool_limits

from tacgen_lib.generate.baselines import target_specs
from tacgen_lib.generate.blocks import feature_block
from tacgen_lib.io import edges
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.fit import fit_probe


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default="results", help="a finished run's results folder")
    ap.add_argument("--corpus", default="sim_paired")
    ap.add_argument("--target", default="hardness")
    ap.add_argument("--cell", default="ddim/1/25", help="sampler/guidance/steps")
    ap.add_argument("--repeats", default="1,5,10,20")
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--bootstrap", type=int, default=1000)
    ap.add_argument("--configfile", default="config/config.yaml", help="the run's config")
    tiny = {"configfile": TINY_CONFIG, "cell": "ddim/2/3", "repeats": "1,2", "draws": 2}
    args = parse_args(ap, {**tiny, "bootstrap": 50})
    results = Path(args.results)
    cfg = run_config(args.configfile)
    sampler, guidance, steps = args.cell.split("/")
    seed = cfg["generate"]["seeds"][0]
    manifest = edges.read(results / "corpus/manifest.parquet").frame
    splits = edges.read(results / "corpus/splits.parquet").frame

    def vectors(path: Path, column: str) -> dict:
        edge = edges.read(path, columns=[column])
        return dict(zip(edge.ids, edge.vectors[column], strict=True))

    vision = vectors(results / f"features/{args.corpus}/vision.parquet", "vit")
    cell = f"sampler~{sampler}/guidance~{guidance}/steps~{steps}"
    gen = vectors(results / f"generate/{args.corpus}/seed~{seed}/{cell}/t_gen.parquet", "t_gen")
    for repeats in (int(r) for r in args.repeats.split(",")):
        (spec,) = [
            s
            for s in target_specs(
                manifest,
                splits,
                corpus=args.corpus,
                targets=cfg["generate"]["corpora"][args.corpus],
                corpus_config=cfg["corpora"][args.corpus],
                probes_config=cfg["probes"],
                probe_seed=cfg["probes"]["seeds"][0],
                rule="bench_cv_repeats",
                cv_repeats=repeats,
            )
            if s.name == args.target
        ]
        rows = spec.rows
        v_tr, v_te = feature_block(vision, rows.train_ids), feature_block(vision, rows.test_ids)
        g_tr, g_te = feature_block(gen, rows.train_ids), feature_block(gen, rows.test_ids)
        deltas, above, chosen = [], 0, set()
        t0 = time.perf_counter()
        for fold_seed in range(args.draws):
            ps = dataclasses.replace(spec.settings, seed=fold_seed, resample_seed=0)
            with threadpool_limits(1):
                pv = fit_probe(v_tr, rows.y_train, v_te, ps)
                pg = fit_probe(np.hstack([v_tr, g_tr]), rows.y_train, np.hstack([v_te, g_te]), ps)
            boot = fixed_test_bootstrap(
                rows.y_test,
                pv.pred_test,
                pg.pred_test,
                ps.metric,
                n_resamples=args.bootstrap,
                seed=0,
                strata=rows.strata_test,
            )
            deltas.append(boot["delta"])
            above += boot["ci_low"] > 0
            chosen.add((float(pv.reg), float(pg.reg)))
        d = np.array(deltas)
        print(
            f"{args.corpus} {args.target} {args.cell}, cv_repeats {repeats}: Delta_gen over "
            f"{args.draws} fold draws {d.min():+.3f} .. {d.max():+.3f}, sd {d.std(ddof=1):.3f}; "
            f"CI above 0 in {above}/{args.draws}; (V, V+T_gen) regularisers {sorted(chosen)}; "
            f"{time.perf_counter() - t0:.1f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
