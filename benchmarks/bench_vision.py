"""Which vision side sees what a natural frame shows: candidate V backbones, each timed and each
scored by the visibility check's own probes (`tacgen_lib.generate.visibility`).

Reads a finished run (its corpus, splits and, for the run's own V, its feature edge) and, on one
natural corpus (default: the first of the regime's rho grid), prints for every candidate V the
seconds it took to make (pretraining) and to extract, and the linear / nonlinear probe accuracy
of colour, texture and the appearance class on the corpus's test rows (fitted on every non-test
row; pretraining reads train rows only), beside the gate of config ``features.visibility``:

  run V         the run's own vision feature edge (whatever config made it)
  pixel-V       the run's raw-pixel V (features.pixel_size), the paper's controlled baseline
  random ResNet resnet_tiny at its seeded random init, no training (the control a learnt V
                must beat)
  SimCLR        resnet_tiny pretrained by `features.simclr.pretrain_simclr` on this corpus's
                train frames (the run's V learns from every corpus of features.pretrain.corpus),
                once per --grey value (greyscale views trade colour for texture) and per pool
                (its projection reads that pool's feature)

Each ResNet is read with every pool of --pools: its last stage's average (cls) and its stage
statistics (stages, `resnet.ResNet.stage_statistics`).

    .venv/bin/python benchmarks/bench_vision.py --results results --grey 0 0.1 0.5
        [--configfile config/config.yaml]

`--configfile` names the run's config (merged over config/config.yaml as Snakemake merges
its own `--configfile`).

Every figure is measured in this run; nothing is compared with a stored number.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from machine import TINY_CONFIG, parse_args, run_config
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.looks import visible_factors
from tacgen_lib.features.extract import extract_features
from tacgen_lib.features.resnet import random_resnet
from tacgen_lib.features.settings import FeatureSettings, SimclrSettings
from tacgen_lib.features.simclr import pretrain_simclr
from tacgen_lib.generate.visibility import (
    VisibilityCorpus,
    VisibilitySettings,
    visibility_check,
    visibility_mlp,
    visibility_probe,
)
from tacgen_lib.io import edges
from tacgen_lib.preprocess.frames import decode_frames

FACTORS = ("colour", "texture", "appearance")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", default="results", help="a finished run's results folder")
    ap.add_argument(
        "--configfile", "--config", default="config/config.yaml", help="the run's config"
    )
    ap.add_argument("--corpus", default="sim_natural_r0", help="a natural corpus of the run")
    ap.add_argument("--epochs", type=int, default=None, help="SimCLR epochs (config's if unset)")
    ap.add_argument(
        "--grey", type=float, nargs="*", default=None, help="SimCLR grey values (config's)"
    )
    ap.add_argument(
        "--pools", nargs="*", default=["cls", "stages"], help="ResNet pools (extract.POOLS)"
    )
    ap.add_argument(
        "--image-size", type=int, default=None, help="default: the run's vision backbone's"
    )
    ap.add_argument("--threads", type=int, default=2)
    tiny = {"configfile": TINY_CONFIG, "epochs": 1, "grey": [0.0], "pools": ["stages"]}
    tiny["threads"] = 1
    args = parse_args(ap, tiny)
    torch.set_num_threads(args.threads)
    config = run_config(args.configfile)
    feat = config["features"]
    size = args.image_size or FeatureSettings.for_backbone(feat, "vision").image_size
    res = Path(args.results)

    splits = edges.read(res / "corpus/splits.parquet").frame
    split = splits.loc[splits["corpus"] == args.corpus].set_index("sample_id")["split"]
    train = sorted(split.index[split != "test"])
    test = sorted(split.index[split == "test"])
    fit_rows = sorted(split.index[split == "train"])  # pretraining: train rows only
    samples = edges.read(res / f"corpus/{args.corpus}/samples.parquet").frame
    ids = samples["sample_id"].astype(str).to_numpy()
    frames = decode_frames(samples, "rgb", where=f"{args.corpus}/samples.parquet")
    factors = visible_factors(samples, appearance_class=True)
    visibility = VisibilitySettings.from_config(feat.get("visibility"))
    probe = visibility_probe(config["probes"], config["probes"]["seeds"][0], visibility)
    mlp = visibility_mlp(config["probes"])  # as rule visibility_check
    print(
        f"corpus {args.corpus}: {len(train)} non-test rows ({len(fit_rows)} train), "
        f"{len(test)} test; input {size} px; torch threads {args.threads}"
    )

    def scored(name: str, vectors: np.ndarray, make_s: float, extract_s: float) -> dict:
        corpus = VisibilityCorpus(
            args.corpus, dict(zip(ids, vectors, strict=True)), factors, train, test
        )
        with threadpool_limits(1):
            rows = visibility_check([corpus], probe, visibility, mlp=mlp, workers=args.threads)
        out = {"V": name, "dim": vectors.shape[1], "make s": make_s, "extract s": extract_s}
        for _, r in rows.loc[rows["factor"].isin(FACTORS)].iterrows():
            out[f"{r['factor']} {r['probe'][:3]}"] = round(float(r["score"]), 3)
        print(f"  {name}: done", flush=True)
        return out

    table = []
    edge = res / f"features/{args.corpus}/vision.parquet"
    for column, name in (("vit", "run V"), ("pixel", "pixel-V")):
        vectors = edges.read_vector_map(edge, column)
        vec = np.stack([vectors[i] for i in ids]).astype(np.float32)
        table.append(scored(name, vec, float("nan"), float("nan")))

    def extracted(model: torch.nn.Module, pool: str) -> tuple[np.ndarray, float]:
        t0 = time.perf_counter()
        vec = extract_features(
            model, frames, image_size=size, batch_size=128, pool=pool, device="cpu"
        )
        return vec, time.perf_counter() - t0

    for pool in args.pools:
        vec, ext = extracted(random_resnet("resnet_tiny", seed=0), pool)
        table.append(scored(f"random ResNet, {pool}", vec, 0.0, ext))
    position = {sid: i for i, sid in enumerate(ids)}
    train_frames = frames[[position[s] for s in fit_rows]]
    base = SimclrSettings.from_config(feat.get("simclr"))
    if args.epochs:
        base = replace(base, epochs=args.epochs)
    for grey in [base.grey] if args.grey is None else args.grey:
        settings = replace(base, grey=grey)
        for pool in args.pools:  # the projection reads what the features read (simclr)
            t0 = time.perf_counter()
            result = pretrain_simclr(
                train_frames, settings, arch="resnet_tiny", image_size=size, pool=pool, device="cpu"
            )
            made = time.perf_counter() - t0
            vec, ext = extracted(result.backbone(), pool)
            name = f"SimCLR {settings.epochs} ep, grey {grey:g}, {pool}"
            table.append(scored(name, vec, made, ext))
    # the run's own edges were made by the run: their seconds are not this benchmark's ("-")
    text = pd.DataFrame(table).to_string(index=False, na_rep="-", float_format="{:.3g}".format)
    print(text)
    print("gate (nonlinear):", dict(visibility.gate))


if __name__ == "__main__":
    main()
