"""The scenes of config/scenes.yaml for tests that simulate whole shards: settling cut to 80
steps where a scene does not set it, so a shard takes seconds (a plain module: pytest puts
tests/ on sys.path, like snakemake_run.py), and the gel's ray-cast height field."""

from __future__ import annotations

import yaml
from snakemake_run import ROOT


def fast_scenes() -> dict:
    """Scene name -> declaration, each with ``settle_steps`` 80 unless it sets its own."""
    scenes = yaml.safe_load((ROOT / "config/scenes.yaml").read_text())
    for decl in scenes.values():
        decl.setdefault("settle_steps", 80)
    return scenes


def gel_heights(rt, optics, *, directions=None, site=None):
    """`tactile.height_field_rays` of the runtime's active object under the gel, through
    `optics` (`directions`: its ray directions, computed if None), the gel at the model's site
    `site` (an id), else at the origin, unrotated."""
    import numpy as np

    from tacgen_lib.corpus.sim import tactile

    if site is None:
        origin, frame = np.zeros(3), np.eye(3).ravel()
    else:
        origin, frame = rt.data.site_xpos[site], rt.data.site_xmat[site]
    if directions is None:
        directions = tactile.ray_directions(optics)
    return tactile.height_field_rays(
        rt.model, rt.data, rt.active_geom, origin, frame, optics, directions
    )
