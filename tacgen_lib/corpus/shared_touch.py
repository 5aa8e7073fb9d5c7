"""Corpora of one rho grid share their touch: the natural design's corpora differ only in what
their objects look like (`tacgen_lib.corpus.sim.corpus.simulate_shards` presses each sample
once for the whole grid), so the tactile features of one serve them all once their frames are
checked byte-identical (rule share_natural_touch). Their looks are shared too: a sample's
appearance class at any rho is the one it draws at rho = 0 or the one at rho = 1, so a corpus
between the grid's ends has each RGB frame of one of theirs (`frame_twins`, rule
share_natural_vision). Kept apart from the simulator: a job that shares features imports
pandas, not MuJoCo."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

__all__ = ["frame_twins", "shared_vectors", "touch_twins"]


def touch_twins(
    source: pd.DataFrame, target: pd.DataFrame, *, where: str = "share_natural_touch"
) -> dict[str, str]:
    """Source sample_id -> the target's sample_id of the same sample, for two corpora of one
    rho grid (`simulate_shards`): sample i of each, whose touch must be byte-identical.

    source, target: `sample_id` and `tactile` (PNG bytes) of each corpus edge. Raises
    ValueError naming `where` and the first sample whose index has no twin or whose tactile
    frames differ: then the corpora are not one grid, and their features cannot be shared.
    """

    twins = frame_twins(target, [source], column="tactile", where=where)
    return {sid: tid for tid, (_, sid) in twins.items()}


def frame_twins(
    target: pd.DataFrame,
    sources: list[pd.DataFrame],
    *,
    column: str = "rgb",
    where: str = "share_natural_vision",
) -> dict[str, tuple[int, str]]:
    """Target sample_id -> (k, sample_id of the same sample in ``sources[k]``) for the first
    source whose `column` frame is byte-identical to the target's: every frame of a corpus
    between a rho grid's ends is one of the ends' (module docstring).

    target, sources: `sample_id` and `column` (PNG bytes) of corpus edges of one rho grid.
    Raises ValueError naming `where` and the first sample whose index is missing from a
    source, or whose frame is none of the sources' (then the corpora are not one grid).
    """
    dst = _by_index(target, column)
    srcs = [_by_index(s, column) for s in sources]
    for src in srcs:
        _same_samples(src, dst, where)
    out: dict[str, tuple[int, str]] = {}
    for k, (tid, frame) in dst.items():
        for j, src in enumerate(srcs):
            sid, other = src[k]
            if frame is not None and other is not None and bytes(frame) == bytes(other):
                out[tid] = (j, sid)
                break
        else:
            raise ValueError(
                f"{where}: sample_id {tid!r} has {column} bytes other than "
                f"{', '.join(repr(src[k][0]) for src in srcs)}: the corpora are not one rho "
                "grid, so its features cannot be shared"
            )
    return out


def shared_vectors(
    ids: Sequence[str],
    twins: Mapping[str, tuple[int, str]],
    sources: Sequence[tuple[Sequence[str], Mapping[str, np.ndarray]]],
) -> dict[str, np.ndarray]:
    """The target's vector columns for its rows `ids`: row i is the row of its twin
    (`frame_twins`: source k, sample_id) in ``sources[k]`` = (sample_ids, name -> (n, d)).
    Raises ValueError when the sources' columns differ in names, widths or dtypes."""
    first = sources[0][1]
    for _, vectors in sources[1:]:
        if {k: (v.shape[1], v.dtype) for k, v in vectors.items()} != {
            k: (v.shape[1], v.dtype) for k, v in first.items()
        }:
            raise ValueError("shared_vectors: the source corpora's feature columns differ")
    rows = [{str(i): r for r, i in enumerate(src_ids)} for src_ids, _ in sources]
    pick = [twins[str(i)] for i in ids]
    source = np.array([k for k, _ in pick], dtype=np.int64)
    row = np.array([rows[k][sid] for k, sid in pick], dtype=np.int64)
    out = {}
    for name, v in first.items():
        col = np.empty((len(pick), v.shape[1]), dtype=v.dtype)
        for k, (_, vectors) in enumerate(sources):
            mine = source == k
            col[mine] = vectors[name][row[mine]]
        out[name] = col
    return out


def _by_index(frame: pd.DataFrame, column: str) -> dict[str, tuple[str, bytes]]:
    """Sample index ("<corpus>-<i:06d>" -> i) -> (sample_id, the `column` frame)."""
    ids = frame["sample_id"].astype(str)
    index = ids.str.rsplit("-", n=1).str[-1]
    return dict(zip(index, zip(ids, frame[column], strict=True), strict=True))


def _same_samples(src: dict, dst: dict, where: str) -> None:
    if src.keys() != dst.keys():
        odd = sorted(src.keys() ^ dst.keys())[0]
        raise ValueError(
            f"{where}: sample index {odd} is in one corpus of the rho grid and not the other "
            f"({len(src)} against {len(dst)} samples)"
        )
