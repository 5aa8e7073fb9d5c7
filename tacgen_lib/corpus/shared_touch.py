"""Corpora of one rho grid share their touch: the natural design's corpora differ only in what
their objects look like (`tacgen_lib.corpus.sim.corpus.simulate_shards` presses each sample
once for the whole grid), so the tactile features of one serve them all once their frames are
checked byte-identical (rule share_natural_touch). Kept apart from the simulator: a job that
shares features imports pandas, not MuJoCo."""

from __future__ import annotations

import pandas as pd

__all__ = ["touch_twins"]


def touch_twins(
    source: pd.DataFrame, target: pd.DataFrame, *, where: str = "share_natural_touch"
) -> dict[str, str]:
    """Source sample_id -> the target's sample_id of the same sample, for two corpora of one
    rho grid (`simulate_shards`): sample i of each, whose touch must be byte-identical.

    source, target: `sample_id` and `tactile` (PNG bytes) of each corpus edge. Raises
    ValueError naming `where` and the first sample whose index has no twin or whose tactile
    frames differ: then the corpora are not one grid, and their features cannot be shared.
    """

    def by_index(frame: pd.DataFrame) -> dict[str, tuple[str, bytes]]:
        ids = frame["sample_id"].astype(str)
        index = ids.str.rsplit("-", n=1).str[-1]  # "<corpus>-<i:06d>"
        return dict(zip(index, zip(ids, frame["tactile"], strict=True), strict=True))

    src, dst = by_index(source), by_index(target)
    if src.keys() != dst.keys():
        odd = sorted(src.keys() ^ dst.keys())[0]
        raise ValueError(
            f"{where}: sample index {odd} is in one corpus of the rho grid and not the other "
            f"({len(src)} against {len(dst)} samples)"
        )
    out = {}
    for k, (sid, tac) in src.items():
        tid, ttac = dst[k]
        if tac is None or ttac is None or bytes(tac) != bytes(ttac):
            raise ValueError(
                f"{where}: sample_id {tid!r} has tactile bytes other than {sid!r}: the corpora "
                "do not share their touch, so their tactile features cannot be shared"
            )
        out[sid] = tid
    return out
