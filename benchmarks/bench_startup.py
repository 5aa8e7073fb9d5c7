"""What a job pays before it runs: the import seconds of each workflow script against the
heavy libraries its own work needs (same run). Prints figures; not a test.

Every Snakemake job runs one `workflow/scripts/*.py` in a fresh interpreter, and most jobs of
`config/test.yaml` are short, so their CPU time is mostly imports. For each script this runs
its top-level import statements (read with `ast`; the script body is not executed) in a fresh
interpreter, best of `--repeats`, and prints:

- import: process CPU seconds (and wall seconds) of those imports;
- loaded: the heavy libraries they end up loading (`HEAVY`; scipy.stats implies scipy,
  matplotlib.pyplot implies matplotlib);
- floor: the seconds of a fresh interpreter importing only the heavy libraries the script's
  job needs (`NEEDS`, read from the code the job calls: its own imports, and the library
  functions it calls that use one at run time; e.g. a probe job needs scikit-learn because its
  controls count scikit-learn's convergence warnings). A script whose job needs none has
  floor 0;
- waste = import - floor (none below the floor), and import / floor.

An import below its floor means the job pays the rest when it calls the function that
imports the library: that part is deferred, not saved. With Snakemake at hand, the totals are
also weighted by the number of jobs of each rule in a dry run of `config/test.yaml` (rules map
to scripts through the `script:` lines of `rules/*.smk`).

    .venv/bin/python benchmarks/bench_startup.py [--repeats 3] [--root .] [--scripts a,b]
        [--no-dry-run]

`--root` measures another checkout (e.g. an unpacked earlier commit) with this benchmark's
table; its `tacgen_lib` is imported, never the installed one.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import machine
from machine import parse_args

HERE = Path(__file__).resolve().parents[1]

#: the libraries whose import dominates a short job, most specific first
HEAVY = (
    "torch",
    "sklearn",
    "scipy.stats",
    "scipy",
    "matplotlib.pyplot",
    "matplotlib",
    "mujoco",
    "cv2",
    "pandas",
)

_TABLE_FIGURES = "pandas matplotlib.pyplot"
_SIM = "mujoco cv2 scipy.special pandas"
#: script -> the heavy libraries its job needs (imported together for the floor)
NEEDS: dict[str, str] = {
    "aggregate_align": _TABLE_FIGURES,
    "aggregate_backbones": "pandas",
    "aggregate_generate": _TABLE_FIGURES + " scipy.stats",  # cross_seed_interval: t quantile
    "aggregate_language": "pandas",
    "aggregate_pixel": _TABLE_FIGURES + " cv2 scipy",  # PNG frames; the filmstrip's Laplacian
    "aggregate_policy": _TABLE_FIGURES,  # the oracle's sweep samples episodes in numpy
    "aggregate_probes": _TABLE_FIGURES + " scipy.stats",  # Benjamini-Hochberg
    "aggregate_regime": _TABLE_FIGURES,
    "aggregate_robustness": _TABLE_FIGURES,
    "background_subtract": "pandas cv2",
    "collect_demos": _SIM,
    "corpus_examples": _TABLE_FIGURES + " scipy.stats cv2",  # binomtest; PNG decoding
    "cost_knob_points": "pandas scipy.stats",  # the bootstrap knob's chi-square interval
    "cost_of_accuracy": _TABLE_FIGURES,
    "edge_manifest": "pandas",
    "evaluate_generator": "pandas sklearn",
    "evaluate_pixel_generators": "torch pandas sklearn cv2 scipy",  # ViT, probes, SSIM
    "extract_features": "torch pandas cv2",
    "family_probe": "pandas sklearn",
    "findings": "pandas scipy.stats",  # cross_seed_interval
    "fit_generator_baselines": "pandas sklearn scipy.spatial",  # Nystroem features
    "fuse_manifest": "pandas",
    "ingest_tvl": "pandas cv2",
    "language_evidence": "pandas sklearn",
    "make_splits": "pandas sklearn",  # train_test_split
    "merge_corpus": "pandas",
    "palpate": "torch " + _SIM,
    "pixel_curve_point": "torch pandas sklearn",  # heads, then the probes
    "policy_regression": "pandas sklearn",
    "pretrain_backbone": "torch pandas cv2",
    "pretrain_curve": _TABLE_FIGURES,
    "pretrained_vs_random": "torch pandas sklearn cv2",
    "probe": "pandas sklearn",
    "probe_training_size": "pandas sklearn",
    "probe_within_scale": "pandas sklearn",
    "project_aligned": "torch pandas",
    "visibility_check": "pandas sklearn",
    "regime_evaluate": "pandas sklearn",
    "regime_generators": "torch pandas",
    "rollout_policy": "torch " + _SIM,
    "sample_generator": "",
    "sample_pixel_generator": "torch pandas cv2",  # + diffusers for the DDPM's arms
    "share_natural_touch": "pandas",
    "share_natural_vision": "pandas",
    "simulate_corpus": _SIM,
    "train_generator": "torch pandas",
    "train_heads": "torch pandas",
    "train_pixel_generator": "torch pandas cv2",  # + diffusers for the DDPM
    "train_policy": "torch pandas",
    "transfer_evaluate": _TABLE_FIGURES + " sklearn",  # logistic probes, the page's figure
}

CHILD = """\
import json, sys, time
w0, c0 = time.perf_counter(), time.process_time()
exec(compile({src!r}, {name!r}, "exec"), {{"__name__": "__bench__"}})
wall, cpu = time.perf_counter() - w0, time.process_time() - c0
lib = sys.modules.get("tacgen_lib")
print(json.dumps({{"wall": wall, "cpu": cpu, "lib": getattr(lib, "__file__", None),
                  "loaded": [h for h in {heavy!r} if h in sys.modules]}}))
"""


def top_level_imports(script: Path) -> str:
    """The script's module-level import statements as source (`from __future__` left out)."""
    tree = ast.parse(script.read_text(), filename=str(script))
    keep = [
        node
        for node in tree.body
        if isinstance(node, ast.Import)
        or (isinstance(node, ast.ImportFrom) and node.module != "__future__")
    ]
    return "\n".join(ast.unparse(node) for node in keep)


def measure(src: str, name: str, root: Path, repeats: int) -> dict:
    """Best CPU and wall seconds of `src` in a fresh interpreter at `root`, and what it loaded."""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }
    code = CHILD.format(src=src, name=name, heavy=HEAVY)
    best: dict | None = None
    for _ in range(repeats):
        out = subprocess.run(
            [sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True
        )
        if out.returncode:
            raise SystemExit(f"{name}: its imports failed:\n{out.stderr}")
        got = json.loads(out.stdout.strip().splitlines()[-1])
        if got["lib"] and not Path(got["lib"]).resolve().is_relative_to(root.resolve()):
            raise SystemExit(f"{name}: imported {got['lib']}, not the tacgen_lib of {root}")
        if best is None:
            best = got
        else:
            best["cpu"], best["wall"] = min(best["cpu"], got["cpu"]), min(best["wall"], got["wall"])
    assert best is not None
    return best


def shown(loaded: list[str]) -> str:
    """The loaded heavy libraries, without those implied by a more specific one."""
    implied = {"scipy": "scipy.stats", "matplotlib": "matplotlib.pyplot"}
    return " ".join(h for h in loaded if implied.get(h) not in loaded)


def job_counts(root: Path) -> Counter[str] | None:
    """script -> jobs of its rules in a dry run of config/test.yaml (None without Snakemake)."""
    snakemake = Path(sys.executable).parent / "snakemake"
    if not snakemake.exists():
        return None
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [str(snakemake), "-n", "--configfile", "config/test.yaml"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
    )
    stats = (proc.stdout + proc.stderr).split("Job stats:")
    if proc.returncode or len(stats) < 2:
        print(f"(no dry run: snakemake exited {proc.returncode})")
        return None
    rule_jobs = {
        rule: int(n)
        for rule, n in re.findall(r"(?m)^(\w+)\s+(\d+)$", stats[1].split("\n\n")[0])
        if rule != "total"
    }
    counts: Counter[str] = Counter()
    for smk in sorted((root / "rules").glob("*.smk")):
        for block in re.split(r"(?m)^(?=rule )", smk.read_text())[1:]:
            rule = re.match(r"rule (\w+):", block).group(1)
            script = re.search(r'script:\n\s+"\.\./workflow/scripts/(\w+)\.py"', block)
            if script and rule in rule_jobs:
                counts[script.group(1)] += rule_jobs[rule]
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--root", type=Path, default=HERE, help="the checkout to measure")
    ap.add_argument("--scripts", default="", help="comma-separated script names (default all)")
    ap.add_argument("--no-dry-run", action="store_true", help="skip the job-count weighting")
    args = parse_args(ap, {"repeats": 1, "scripts": "merge_corpus"})
    root = args.root.resolve()
    scripts = sorted((root / "workflow" / "scripts").glob("*.py"))
    if args.scripts:
        scripts = [s for s in scripts if s.stem in args.scripts.split(",")]
    print(f"machine: {machine.describe()}")
    print(f"root: {root}; best of {args.repeats}; process CPU seconds (wall in brackets)")
    jobs = None if args.no_dry_run else job_counts(root)
    floors: dict[str, dict] = {}
    head = (
        f"{'script':<24} {'jobs':>4} {'import':>14} {'floor':>6} {'waste':>6} {'ratio':>6}"
        f"  loaded / needed"
    )
    print(head)
    totals = Counter()
    for script in scripts:
        name = script.stem
        got = measure(top_level_imports(script), name, root, args.repeats)
        needs = NEEDS.get(name)
        if needs is None:
            print(f"{name:<24} (not in NEEDS: add it)")
            needs = ""
        key = " ".join(sorted(needs.split()))
        if key and key not in floors:
            src = "\n".join(f"import {m}" for m in key.split())
            floors[key] = measure(src, f"floor:{key}", root, args.repeats)
        floor = floors[key]["cpu"] if key else 0.0
        n = jobs.get(name, 0) if jobs is not None else 0
        ratio = f"{got['cpu'] / floor:6.2f}" if floor else f"{'-':>6}"
        print(
            f"{name:<24} {n:>4} {got['cpu']:6.2f} ({got['wall']:5.2f}) {floor:6.2f} "
            f"{got['cpu'] - floor:6.2f} {ratio}  {shown(got['loaded']) or '-'} / {needs or '-'}"
        )
        waste = max(0.0, got["cpu"] - floor)  # below the floor is deferral, not saving
        totals.update(
            {
                "import": got["cpu"],
                "floor": floor,
                "waste": waste,
                "w_import": n * got["cpu"],
                "w_floor": n * floor,
                "w_waste": n * waste,
            }
        )
    print(
        f"sum over {len(scripts)} scripts: import {totals['import']:.2f} s, "
        f"floor {totals['floor']:.2f} s, waste {totals['waste']:.2f} s"
    )
    if jobs is not None:
        print(
            f"weighted by the {sum(jobs.get(s.stem, 0) for s in scripts)} jobs of these scripts "
            f"in config/test.yaml: import {totals['w_import']:.2f} s, "
            f"floor {totals['w_floor']:.2f} s, waste {totals['w_waste']:.2f} s"
        )
    print(
        "import = top-level imports of the script; floor = importing only NEEDS; "
        "waste = import - floor; ratio = import / floor. An import below its floor is paid "
        "later, when the job calls the function that imports the library: the totals' waste "
        "sums only the scripts above their floor."
    )


if __name__ == "__main__":
    main()
