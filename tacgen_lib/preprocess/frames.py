"""Image columns of corpus edges as uint8 arrays: decoding, per-sensor backgrounds, variants.

Edges carry PNG bytes (tacgen_lib.io.images); the numerics want (N, H, W, 3) uint8 stacks. This
module does that conversion once, with errors that name the edge, the column and the sample.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np
import pandas as pd

from tacgen_lib.io.images import decode_png, encode_png
from tacgen_lib.preprocess.background import background_subtract

__all__ = ["decode_frames", "sensor_background_map", "subtract_backgrounds"]


def decode_frames(frame: pd.DataFrame, column: str, *, where: str = "edge") -> np.ndarray:
    """Stack the PNG images of `column` into (N, H, W, 3) uint8; all frames must share a shape."""
    if column not in frame.columns:
        raise ValueError(f"{where}: no image column {column!r}")
    images = []
    for sid, data in zip(frame["sample_id"], frame[column], strict=True):
        if data is None:
            raise ValueError(f"{where}: sample_id {sid!r} has no image in column {column!r}")
        images.append(decode_png(data, where=f"{where}: sample_id {sid!r} column {column!r}"))
    if not images:
        return np.empty((0, 1, 1, 3), dtype=np.uint8)
    shapes = Counter(img.shape for img in images)
    if len(shapes) > 1:
        # name the odd one out: the first frame whose size differs from most frames'
        common = shapes.most_common(1)[0][0]
        i = next(i for i, img in enumerate(images) if img.shape != common)
        raise ValueError(
            f"{where}: sample_id {frame['sample_id'].iloc[i]!r} has a {images[i].shape} image in "
            f"column {column!r}, the others are {common}"
        )
    return np.stack(images)


def sensor_background_map(
    sensors: pd.DataFrame, *, where: str = "sensors"
) -> dict[str, np.ndarray]:
    """sensor_id -> decoded background image."""
    return {
        sid: decode_png(data, where=f"{where}: sensor {sid!r}")
        for sid, data in zip(sensors["sensor_id"], sensors["background"], strict=True)
    }


def subtract_backgrounds(
    samples: pd.DataFrame,
    backgrounds: dict[str, np.ndarray],
    variant: str,
    *,
    where: str = "samples",
    progress: Callable[[int], None] | None = None,
) -> pd.DataFrame:
    """Apply one background-subtraction variant to every tactile frame, each with its own
    sensor's background. Returns sample_id, sensor_id and `tactile_proc` (PNG bytes).

    Samples whose sensor has no background (a real corpus's rows whose background file its
    ingest did not find) are refused before any frame is processed, in one error naming
    `where`, how many there are and their sample_ids and sensors.
    """
    lacking = [
        (sid, sensor)
        for sid, sensor in zip(samples["sample_id"], samples["sensor_id"], strict=True)
        if sensor not in backgrounds
    ]
    if lacking:
        shown = ", ".join(f"{sid!r} (sensor {sensor!r})" for sid, sensor in lacking[:10])
        more = f" and {len(lacking) - 10} more" if len(lacking) > 10 else ""
        raise ValueError(
            f"{where}: {len(lacking)} of {len(samples)} samples have no tactile background to "
            f"subtract: {shown}{more}; their sensors have no background image (a real "
            "corpus's ingest log lists the rows whose background file it did not find): "
            f"restore those files or drop the samples (sensors with one: {sorted(backgrounds)[:10]})"
        )
    out = []
    for i, row in enumerate(samples[["sample_id", "sensor_id", "tactile"]].itertuples(index=False)):
        sid, sensor, data = row
        tac = decode_png(data, where=f"{where}: sample_id {sid!r} column 'tactile'")
        try:
            proc = background_subtract(tac, backgrounds[sensor], variant)
        except ValueError as exc:
            raise ValueError(
                f"{where}: sample_id {sid!r} column 'tactile' (sensor {sensor!r}): {exc}"
            ) from exc
        out.append((sid, sensor, encode_png(proc, compression=1)))
        if progress is not None:
            progress(i + 1)
    return pd.DataFrame(out, columns=["sample_id", "sensor_id", "tactile_proc"])
