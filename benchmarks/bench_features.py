"""Feature-extraction throughput per backbone, DINO pretraining cost, and whether DINO helps.

Prints, measured in this run:
  1. images/s of `extract_features` for vit_tiny, vit_small, vit_base at --image-size, with
     the pixel-V baseline (`pixel_features`) as the reference (ratio = backbone / pixel-V);
  2. seconds per DINO epoch of the in-workflow arch (--dino-arch) on --dino-n frames;
  3. (--probe) a linear probe (standardised logistic regression) on a structured synthetic
     task, "which shape is drawn" (disc / square / triangle / cross, random colours, sizes and
     positions), using frozen features of (a) a randomly initialised backbone, (b) the same arch
     after DINO pretraining on the training frames only, (c) pixel-V. Test accuracy on held-out
     frames; chance is 0.25.

Random weights are used for the throughput rows: speed does not depend on the values.

    .venv/bin/python benchmarks/bench_features.py --image-size 56 --threads 2
    .venv/bin/python benchmarks/bench_features.py --image-size 56 --probe --dino-epochs 10
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
import torch
from machine import parse_args
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tacgen_lib.features.dino import pretrain_dino
from tacgen_lib.features.extract import extract_features, pixel_features
from tacgen_lib.features.settings import DinoSettings
from tacgen_lib.features.vit import build_vit


def shapes_dataset(
    n: int, size: int, seed: int, radius: tuple[float, float] = (0.15, 0.3)
) -> tuple[np.ndarray, np.ndarray]:
    """n frames (size x size) each with one filled shape; label 0 disc, 1 square, 2 triangle,
    3 cross. Foreground and background colours, size (half-width `radius` x size) and position
    are drawn independently."""
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 4, n)
    frames = np.empty((n, size, size, 3), np.uint8)
    for i, y in enumerate(labels):
        img = np.empty((size, size, 3), np.uint8)
        img[:] = rng.integers(0, 256, 3)
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        r = rng.uniform(*radius) * size
        cx, cy = rng.uniform(r, size - r, 2)
        if y == 0:
            cv2.circle(img, (int(cx), int(cy)), int(r), colour, -1)
        elif y == 1:
            cv2.rectangle(img, (int(cx - r), int(cy - r)), (int(cx + r), int(cy + r)), colour, -1)
        elif y == 2:
            pts = np.array([[cx, cy - r], [cx - r, cy + r], [cx + r, cy + r]], np.int32)
            cv2.fillPoly(img, [pts], colour)
        else:
            t = max(1, int(r / 3))
            cv2.rectangle(img, (int(cx - r), int(cy - t)), (int(cx + r), int(cy + t)), colour, -1)
            cv2.rectangle(img, (int(cx - t), int(cy - r)), (int(cx + t), int(cy + r)), colour, -1)
        frames[i] = img
    return frames, labels


def probe_accuracy(f_train, y_train, f_test, y_test) -> float:
    clf = make_pipeline(StandardScaler(), LogisticRegression(max_iter=3000, C=0.1))
    return float(clf.fit(f_train, y_train).score(f_test, y_test))


def throughput(args: argparse.Namespace) -> None:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (args.n, 240, 320, 3), dtype=np.uint8)  # DIGIT-sized frames
    t0 = time.perf_counter()
    pixel_features(frames, size=(16, 16))
    ref = args.n / (time.perf_counter() - t0)
    print(f"\n[1] extract_features throughput, {args.n} frames 240x320 -> {args.image_size} px")
    print(f"{'backbone':<11}{'dim':>6}{'images/s':>12}{'vs pixel-V':>12}")
    print(f"{'pixel-V':<11}{768:>6}{ref:>12.1f}{1.0:>12.3f}")
    for arch in ("vit_tiny", "vit_small", "vit_base"):
        torch.manual_seed(0)
        model = build_vit(arch, img_size=args.image_size)
        extract_features(
            model, frames[:2], image_size=args.image_size, batch_size=2, device="cpu", pool="cls"
        )  # warm-up
        t0 = time.perf_counter()
        extract_features(
            model,
            frames,
            image_size=args.image_size,
            batch_size=args.batch_size,
            device="cpu",
            pool="cls",
        )
        ips = args.n / (time.perf_counter() - t0)
        print(f"{arch:<11}{model.embed_dim:>6}{ips:>12.1f}{ips / ref:>12.4f}")


def dino_cost(args: argparse.Namespace) -> None:
    frames, _ = shapes_dataset(args.dino_n, args.image_size, seed=1)
    res = pretrain_dino(
        frames,
        DinoSettings(epochs=2, batch_size=64, lr=1e-3, seed=0),
        arch=args.dino_arch,
        image_size=args.image_size,
        device="cpu",
    )
    secs = [r["seconds"] for r in res.curve]
    print(f"\n[2] DINO pretraining, {args.dino_arch}, {args.dino_n} frames, {args.image_size} px")
    print(f"seconds/epoch: first {secs[0]:.1f} (incl. warm-up), second {secs[1]:.1f}")
    print(f"=> {secs[1] / args.dino_n * 1000:.1f} s per 1000 frames per epoch")


def probe(args: argparse.Namespace) -> None:
    size = args.image_size
    frames, labels = shapes_dataset(
        args.probe_train + args.probe_test, size, seed=2, radius=tuple(args.shape_radius)
    )
    tr, te = slice(0, args.probe_train), slice(args.probe_train, None)
    print(
        f"\n[3] linear probe, shape task, {args.probe_train} train / {args.probe_test} test, "
        f"{size} px, DINO {args.dino_epochs} epochs lr {args.dino_lr}"
    )
    t0 = time.perf_counter()
    res = pretrain_dino(
        frames[tr],
        DinoSettings(epochs=args.dino_epochs, batch_size=64, lr=args.dino_lr, seed=0),
        arch=args.dino_arch,
        image_size=size,
        progress=lambda m: print("   ", m),
        device="cpu",
    )
    print(f"    pretraining took {time.perf_counter() - t0:.0f} s")
    torch.manual_seed(0)
    backbones = {"random-init": build_vit(args.dino_arch, img_size=size), "DINO": res.backbone()}
    print(f"{'features':<24}{'test acc':>10}")
    for pool in ("cls", "mean_patch"):
        for name, model in backbones.items():
            f = extract_features(
                model, frames, image_size=size, batch_size=128, pool=pool, device="cpu"
            )
            acc = probe_accuracy(f[tr], labels[tr], f[te], labels[te])
            print(f"{name + ' ' + pool:<24}{acc:>10.3f}")
    pv = pixel_features(frames, size=(16, 16))
    print(f"{'pixel-V':<24}{probe_accuracy(pv[tr], labels[tr], pv[te], labels[te]):>10.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--image-size", type=int, default=56)
    ap.add_argument("--n", type=int, default=64, help="frames for the throughput rows")
    ap.add_argument("--batch-size", type=int, default=32)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--dino-arch", default="vit_tiny")
    ap.add_argument("--dino-n", type=int, default=256, help="frames for the DINO cost row")
    ap.add_argument("--probe", action="store_true", help="run the (slow) linear-probe section")
    ap.add_argument("--probe-train", type=int, default=1000)
    ap.add_argument("--probe-test", type=int, default=400)
    ap.add_argument("--dino-epochs", type=int, default=10)
    ap.add_argument("--dino-lr", type=float, default=1e-3)
    ap.add_argument("--shape-radius", type=float, nargs=2, default=(0.15, 0.3))
    ap.add_argument("--skip-throughput", action="store_true")
    tiny = {"image_size": 28, "n": 4, "batch_size": 2, "threads": 1, "dino_n": 8, "probe": True}
    args = parse_args(ap, {**tiny, "probe_train": 16, "probe_test": 8, "dino_epochs": 1})
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    if not args.skip_throughput:
        throughput(args)
        dino_cost(args)
    if args.probe:
        probe(args)


if __name__ == "__main__":
    main()
