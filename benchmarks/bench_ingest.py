"""Peak memory and wall time of the HCT ingest (rule ingest_tvl) on synthetic trees of a given
number of frames, in the published layout (docs/real_data.md): prints one line per size.

    .venv/bin/python benchmarks/bench_ingest.py --frames 4000 40000
    .venv/bin/python benchmarks/bench_ingest.py --frames 4000 --in-memory   # the whole tables

Each size is ingested in a fresh interpreter (its peak resident memory is that interpreter's
own `ru_maxrss`), streamed as the rule streams it (`tacgen_lib.corpus.ingest.write_ingested`), or
with --in-memory as whole tables (`load_ingested` then `edges.write`, how the ingest worked
before it streamed), for comparison. The tree: data1..data3, trajectories of --per-traj frames,
each with its background; DIGIT frames at the published SSVTP background's size (320 x 240,
rows x columns), camera frames at --rgb-size: seeded images from a small pool, each frame
made its own by a block drawn from its index (so the edge holds every frame's PNG, as a real
one does); every frame is decoded and re-encoded by the ingest.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from machine import parse_args

ROOT = Path(__file__).resolve().parents[1]
TACTILE = (320, 240)
WORDS = ("smooth", "rough", "hard", "soft", "glossy", "bumpy", "textured", "cool")


def _pool(n: int, shape: tuple[int, int], seed: int, tactile: bool) -> list[np.ndarray]:
    """`n` distinct seeded BGR images of `shape`: DIGIT-like (a gradient, a contact blob,
    sensor noise) or camera-like (a colour field with an object)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    images = []
    for _ in range(n):
        img = rng.uniform(60, 160, 3) + 40 * np.stack([xx / w, yy / h, 1 - xx / w], -1)
        cy, cx = rng.uniform(0.3, 0.7) * h, rng.uniform(0.3, 0.7) * w
        blob = np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * (0.15 * min(h, w)) ** 2))
        img += blob[..., None] * rng.uniform(-60, 60, 3)
        img += rng.normal(0, 3 if tactile else 6, img.shape)
        images.append(np.clip(img, 0, 255).astype(np.uint8))
    return images


def _write_unique(image: np.ndarray, index: int, dest: Path) -> None:
    """`image` with a corner block drawn from `index` (so no two frames share their bytes,
    nor their PNG: a Parquet dictionary cannot fold them), as a JPEG at `dest`."""
    frame = image.copy()
    block = np.frombuffer(np.int64(index).tobytes() * 24, dtype=np.uint8)[: 8 * 8 * 3]
    frame[:8, :8] = block.reshape(8, 8, 3)
    dest.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(dest), frame):
        raise OSError(f"cannot write {dest}")


def build_tree(root: Path, frames: int, per_traj: int, rgb_size: tuple[int, int]) -> None:
    """A synthetic hct/ of `frames` rows in the published layout, every frame its own file."""
    tactile = _pool(32, TACTILE, 0, tactile=True)
    rgb = _pool(32, rgb_size, 1, tactile=False)
    rng = np.random.default_rng(2)
    hct = root / "hct"
    rows: dict[str, dict[str, list[list[str]]]] = {
        f"data{d}": {"train": [], "test": []} for d in (1, 2, 3)
    }
    n_traj = -(-frames // per_traj)
    done = 0
    for t in range(n_traj):
        data = f"data{1 + t % 3}"
        traj = f"{t}-{1702507215.615537 + 61.25 * t:.6f}"
        _write_unique(tactile[t % len(tactile)], -1 - t, hct / data / traj / "background.png")
        for k in range(min(per_traj, frames - done)):
            frame = f"{100 + k}-{0.025303125 * (k + 1):.6f}.jpg"
            _write_unique(rgb[(t + k) % len(rgb)], done, hct / data / traj / "vision" / frame)
            _write_unique(
                tactile[(t * 7 + k) % len(tactile)], done, hct / data / traj / "tactile" / frame
            )
            words = rng.choice(len(WORDS), size=int(rng.integers(1, 4)), replace=False)
            rows[data]["test" if k % 10 == 9 else "train"].append(
                [
                    f"{traj}/vision/{frame}",
                    f"{traj}/tactile/{frame}",
                    f"{traj}/background.png",
                    ", ".join(WORDS[i] for i in words),
                ]
            )
            done += 1
    for data, splits in rows.items():
        for split, split_rows in splits.items():
            with (hct / data / f"{split}.csv").open("w", newline="") as handle:
                writer = csv.writer(handle)
                writer.writerow(["url", "tactile", "tactile_background", "caption"])
                writer.writerows(split_rows)


_CHILD = """
import resource, sys, time
from pathlib import Path
from tacgen_lib.corpus.ingest import load_ingested, plan_hct, write_ingested
from tacgen_lib.io import edges
root, out, in_memory = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3] == "1"
t0 = time.perf_counter()
plan = plan_hct(root)
t1 = time.perf_counter()
if in_memory:
    samples, sensors = load_ingested(plan)
    edges.write(out / "samples.parquet", samples)
    edges.write(out / "sensors.parquet", sensors, key="sensor_id")
    n = len(samples)
else:
    n, _ = write_ingested(plan, out / "samples.parquet", out / "sensors.parquet")
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(n, t1 - t0, time.perf_counter() - t1, peak)
"""


def measure(root: Path, out: Path, in_memory: bool) -> tuple[int, float, float, float]:
    """(samples, plan seconds, image seconds, peak resident MiB: the child's own ru_maxrss)
    of one ingest in a fresh interpreter."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, str(root), str(out), "1" if in_memory else "0"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    n, plan_s, image_s, peak = proc.stdout.split()
    return int(n), float(plan_s), float(image_s), float(peak)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[4000, 40000])
    parser.add_argument("--per-traj", type=int, default=100)
    parser.add_argument("--rgb-size", type=int, nargs=2, default=[240, 320], metavar=("H", "W"))
    parser.add_argument("--in-memory", action="store_true", help="whole tables, for comparison")
    parser.add_argument("--dir", type=Path, default=None, help="where to build (default: a tmp)")
    args = parse_args(parser, {"frames": [60], "per_traj": 20})
    base = Path(tempfile.mkdtemp(prefix="bench_ingest_", dir=args.dir))
    try:
        print(
            f"HCT ingest ({'in memory' if args.in_memory else 'streamed'}), tactile "
            f"{TACTILE[0]}x{TACTILE[1]}, camera {args.rgb_size[0]}x{args.rgb_size[1]}, "
            f"row group {'-' if args.in_memory else 'ROW_GROUP_BYTES'}"
        )
        for frames in args.frames:
            root, out = base / f"tree{frames}", base / f"out{frames}"
            t = time.perf_counter()
            build_tree(root, frames, args.per_traj, tuple(args.rgb_size))
            built = time.perf_counter() - t
            n, plan_s, image_s, peak = measure(root, out, args.in_memory)
            size = sum(p.stat().st_size for p in out.glob("*.parquet")) / 2**20
            print(
                f"{n:>7} frames: peak RSS {peak:8.1f} MiB, plan {plan_s:6.1f} s, images "
                f"{image_s:7.1f} s ({1e3 * image_s / n:.1f} ms/frame), edges {size:8.1f} MiB "
                f"(tree built in {built:.1f} s)",
                flush=True,
            )
            shutil.rmtree(root)
            shutil.rmtree(out)
    finally:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
