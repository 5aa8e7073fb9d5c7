"""How long the latent generator must train, and what that buys, against ridge V->T (same run).

On a finished run's features of one corpus, trains `fit_generator` under each setting given
(changes to config ``generate``: the cap ``steps``, ``batch_size``, ``hidden``, ``patience``...;
early stopping on the val split decides where it stops) and prints, per setting: the best
step and the steps run, whether it stopped early, the best val loss, the training seconds, and
the matched-pair cosine of DDIM-25 samples of the test rows at w = 1 and w = 3 (centred on the
real train mean, `fidelity.cosine_pairing`). First the reference measured in the same run:
ridge V->T's conditional mean (`ridge_generator.ridge_generate`) on the same rows.

    .venv/bin/python benchmarks/bench_generator_length.py [--results results]
        [--corpus sim_paired] [--seed 0] [--threads 1] [--configfile config/config.yaml]
        steps=500 steps=3000,batch_size=256

`--configfile` names the run's config (merged over config/config.yaml as Snakemake merges
its own `--configfile`): the settings change its ``generate``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
import torch
from machine import TINY_CONFIG, parse_args, run_config

from tacgen_lib.corpus.splits import ids_in_split
from tacgen_lib.generate.fidelity import cosine_pairing
from tacgen_lib.generate.ridge_generator import ridge_generate
from tacgen_lib.generate.sampling import generate
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.generate.train import fit_generator
from tacgen_lib.io import edges


def parse_setting(text: str, base: GenerateSettings) -> GenerateSettings:
    """ "steps=3000,batch_size=256" -> `base` with those fields, typed as `base`'s."""
    changes = {}
    for item in text.split(","):
        key, _, value = item.partition("=")
        changes[key] = type(getattr(base, key))(value)
    return dataclasses.replace(base, **changes)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("settings", nargs="*", help="key=value[,key=value] changes to generate")
    ap.add_argument("--results", default="results", help="a finished run's results folder")
    ap.add_argument("--corpus", default="sim_paired")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--configfile", default="config/config.yaml", help="the run's config")
    args = parse_args(ap, {"settings": ["steps=20"], "configfile": TINY_CONFIG})
    if not args.settings:
        ap.error("name at least one setting, e.g. steps=500")
    torch.set_num_threads(args.threads)
    results = Path(args.results)
    config = run_config(args.configfile)["generate"]
    base = GenerateSettings.from_config(config)
    splits = edges.read(results / "corpus/splits.parquet").frame
    v = edges.read(results / f"features/{args.corpus}/vision.parquet", columns=["vit"])
    t = edges.read(
        results / f"features/{args.corpus}/tactile~{config['variant']}.parquet", columns=["vit"]
    )
    ids = {s: sorted(ids_in_split(splits, s, args.corpus)) for s in ("train", "val", "test")}
    V = {s: v.subset(i).vectors["vit"].astype(np.float64) for s, i in ids.items()}
    T = {s: t.subset(i).vectors["vit"].astype(np.float64) for s, i in ids.items()}
    centre = T["train"].mean(axis=0)
    every = [i for s in ids for i in ids[s]]
    vision = dict(zip(every, np.vstack([V[s] for s in ids]), strict=True))
    tactile = dict(zip(every, np.vstack([T[s] for s in ids]), strict=True))
    ridge = ridge_generate(vision, tactile, ids["train"], seed=args.seed)
    mean = np.stack([ridge.mean[i] for i in ids["test"]])
    cos, off = cosine_pairing(mean - centre, T["test"] - centre)
    print(
        f"{args.corpus}: {len(ids['train'])} train / {len(ids['val'])} val / "
        f"{len(ids['test'])} test rows; ridge V->T mean (alpha {ridge.alpha:g}): matched cos "
        f"{cos:.3f}, off-diagonal {off:.3f}"
    )
    for text in args.settings:
        settings = parse_setting(text, base)
        t0 = time.perf_counter()
        fit = fit_generator(
            T["train"], V["train"], T["val"], V["val"], settings, seed=args.seed, device="cpu"
        )
        seconds = time.perf_counter() - t0
        cosines = []
        for guidance in (1.0, 3.0):
            gen = generate(
                fit.weights(),
                V["test"].astype(np.float32),
                sampler="ddim",
                steps=25,
                guidance=guidance,
                seed=1,
                eta=settings.eta,
                batch=settings.batch,
            )
            cosines.append(cosine_pairing(gen - centre, T["test"] - centre)[0])
        print(
            f"{text}: best step {fit.best_step} of {fit.steps_run} (early stop "
            f"{fit.stopped_early}), val loss {fit.best_val_loss:.4f}, {seconds:.1f} s; matched "
            f"cos w=1 {cosines[0]:.3f}, w=3 {cosines[1]:.3f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
