"""The scenes of config/scenes.yaml for tests that simulate whole shards: settling cut to 80
steps where a scene does not set it, so a shard takes seconds (a plain module: pytest puts
tests/ on sys.path, like snakemake_run.py)."""

from __future__ import annotations

import yaml
from snakemake_run import ROOT


def fast_scenes() -> dict:
    """Scene name -> declaration, each with ``settle_steps`` 80 unless it sets its own."""
    scenes = yaml.safe_load((ROOT / "config/scenes.yaml").read_text())
    for decl in scenes.values():
        decl.setdefault("settle_steps", 80)
    return scenes
