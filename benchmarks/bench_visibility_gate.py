"""Does the run's V clear the visibility gate whatever its pretraining seed and the CPU's
kernels? The seed × kernels table of what V decodes of the gate corpus.

A gate decision that holds for one pretraining seed on one CPU's kernels only is not a
finding. For every pretraining seed of --seeds and every kernel choice of --variants (native:
this CPU's own; or a variant of `tools/kernel_variants.py`, whose environment picks other BLAS,
oneDNN, torch and numpy kernels), this makes the run's vision backbone again as rule
pretrain_backbone does (`features.backbones.make_backbone`: the train frames of every corpus of
``features.pretrain.corpus``, the config's settings, that seed), reads the gate corpus's
features as rule extract_vision_features does (`FeatureSettings.for_backbone`), and runs the
visibility check on them (`generate.visibility.visibility_check`, the rule's probes), printing
per cell the nonlinear probe's test accuracy on colour, texture and the appearance class with
its 95 % CI, and the gate's decision (`visibility_gate`, config ``features.visibility.gate``).
Each kernel choice runs in its own interpreter (the kernels are chosen at start-up).

    .venv/bin/python benchmarks/bench_visibility_gate.py --results results \\
        [--seeds 0 1 2] [--variants native avx2-2threads] [--threads 2]

Reads a finished run's corpus and splits (the default's, or --configfile's); every figure is
measured in this run, and the seconds each cell took (pretraining and extraction) are printed
beside it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

from machine import ROOT, describe, parse_args, run_config

FACTORS = ("colour", "texture", "appearance")


def cell(config: dict, results: Path, seed: int, threads: int) -> dict:
    """One seed's V made, read and checked in this process's kernels."""
    import numpy as np
    import torch
    from threadpoolctl import threadpool_limits

    from tacgen_lib.corpus.looks import visible_factors
    from tacgen_lib.corpus.splits import ids_in_split
    from tacgen_lib.features.backbones import make_backbone
    from tacgen_lib.features.extract import extract_with
    from tacgen_lib.features.families import BackboneSpec
    from tacgen_lib.features.settings import (
        DinoSettings,
        FeatureSettings,
        MaeSettings,
        SimclrSettings,
        backbone_image_size,
        pretraining_corpora,
    )
    from tacgen_lib.generate.regime_sets import regime_corpora
    from tacgen_lib.generate.visibility import (
        VisibilityCorpus,
        VisibilitySettings,
        visibility_check,
        visibility_gate,
        visibility_mlp,
        visibility_probe,
    )
    from tacgen_lib.io import edges
    from tacgen_lib.preprocess.frames import decode_frames

    torch.set_num_threads(threads)
    feat = config["features"]
    splits = edges.read(results / "corpus/splits.parquet").frame

    def frames(corpus: str, ids=None) -> np.ndarray:
        edge = edges.read(results / f"corpus/{corpus}/samples.parquet", columns=["rgb"])
        edge = edge.subset(ids) if ids is not None else edge
        return decode_frames(edge.frame, "rgb", where=corpus)

    def train_frames() -> np.ndarray:  # as rule pretrain_backbone reads them
        corpora = pretraining_corpora(feat["pretrain"])
        return np.concatenate([frames(c, ids_in_split(splits, "train", corpus=c)) for c in corpora])

    declared = feat["backbones"]["vision"]
    spec = BackboneSpec.from_config(declared)
    simclr = replace(SimclrSettings.from_config(feat.get("simclr")), seed=seed)
    dino = replace(DinoSettings.from_config(feat["pretrain"]), seed=seed)
    mae = replace(MaeSettings.from_config(feat.get("mae")), seed=seed)
    t0 = time.perf_counter()
    model, _, how = make_backbone(
        spec,
        image_size=backbone_image_size(feat, declared),
        dino=dino,
        mae=mae,
        frames=train_frames,
        simclr=simclr,
        device="cpu",
    )
    made = time.perf_counter() - t0
    gated = list(regime_corpora(config.get("regime")))
    if not gated:
        raise SystemExit("bench_visibility_gate: the config has no regime corpus to gate")
    gate_corpus = gated[0]  # the rho grid's first corpus, as rule visibility_check gates it
    samples = edges.read(results / f"corpus/{gate_corpus}/samples.parquet").frame
    t0 = time.perf_counter()
    vec = extract_with(
        model, frames(gate_corpus), FeatureSettings.for_backbone(feat, "vision"), device="cpu"
    )
    extracted = time.perf_counter() - t0
    split = splits.loc[splits["corpus"] == gate_corpus].set_index("sample_id")["split"]
    ids = samples["sample_id"].astype(str).tolist()
    check = VisibilityCorpus(
        gate_corpus,
        dict(zip(ids, vec, strict=True)),
        visible_factors(samples, appearance_class=True),
        train=sorted(split.index[split != "test"]),
        test=sorted(split.index[split == "test"]),
    )
    settings = VisibilitySettings.from_config(feat.get("visibility"))
    probe = visibility_probe(config["probes"], config["probes"]["seeds"][0], settings)
    mlp = visibility_mlp(config["probes"])  # as rule visibility_check
    with threadpool_limits(1):
        rows = visibility_check([check], probe, settings, mlp=mlp, workers=threads)
    gate = visibility_gate(rows, gate_corpus, settings.gate)
    out = {"seed": seed, "corpus": gate_corpus, "backbone": how, "make s": made}
    out["extract s"] = extracted
    for factor in FACTORS:  # the better probe's, as the gate reads it
        g = rows[rows["factor"] == factor]
        if len(g):
            r = g.loc[g["score"].idxmax()]
            out[factor] = [float(r["score"]), float(r["ci_low"]), float(r["ci_high"])]
            out[f"{factor} probe"] = str(r["probe"])
    out["gate"] = "passes" if gate.passed else "fails"
    return out


def variant_env(name: str) -> dict[str, str]:
    """This process's environment with the kernel variables of variant `name` (native: none
    of them)."""
    sys.path.insert(0, str(ROOT / "tools"))
    from kernel_variants import VARIANTS

    names = {v for env, _, _ in VARIANTS.values() for v in env}
    env = {k: v for k, v in os.environ.items() if k not in names}
    if name != "native":
        if name not in VARIANTS:
            raise SystemExit(f"bench_visibility_gate: unknown variant {name!r}: {sorted(VARIANTS)}")
        env.update(VARIANTS[name][0])
    return env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", default="results", help="a finished run's results folder")
    ap.add_argument("--configfile", default=None, help="the run's --configfile (default: none)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--variants", nargs="+", default=["native", "avx2-2threads"])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parse_args(
        ap,
        {"configfile": "config/test.yaml", "seeds": [0], "variants": ["generic"]},
    )
    config = run_config(args.configfile or "config/config.yaml")
    results = Path(args.results).resolve()
    if args.child:  # one kernel choice: every seed, a JSON line each
        for seed in args.seeds:
            print(json.dumps(cell(config, results, seed, args.threads)), flush=True)
        return
    print(describe())
    print(f"gate: {config['features']['visibility']['gate']}")
    rows = []
    for variant in args.variants:
        command = [sys.executable, __file__, "--child", "--results", str(results)]
        command += ["--threads", str(args.threads), "--seeds", *map(str, args.seeds)]
        if args.configfile:
            command += ["--configfile", args.configfile]
        done = subprocess.run(
            command, env=variant_env(variant), capture_output=True, text=True, check=False
        )
        if done.returncode != 0:
            raise SystemExit(f"bench_visibility_gate: {variant} failed:\n{done.stderr[-3000:]}")
        for line in done.stdout.splitlines():
            if line.startswith("{"):
                rows.append({"kernels": variant, **json.loads(line)})
                print(f"  {variant}, seed {rows[-1]['seed']}: done", flush=True)
    header = ["kernels", "seed", *FACTORS, "gate", "make s", "extract s"]
    print("  ".join(header))
    for r in rows:
        cells = [r["kernels"], str(r["seed"])]
        for factor in FACTORS:
            s, lo, hi = r.get(factor, [float("nan")] * 3)
            cells.append(f"{s:.3f} [{lo:.3f}, {hi:.3f}] ({r.get(f'{factor} probe', '-')})")
        cells += [r["gate"], f"{r['make s']:.1f}", f"{r['extract s']:.1f}"]
        print("  ".join(cells))
    decisions = {r["gate"] for r in rows}
    print(f"gate decision: {', '.join(sorted(decisions))} in {len(rows)} cells", end="")
    print("" if len(decisions) == 1 else " (IT DEPENDS ON THE CELL)")


if __name__ == "__main__":
    main()
