"""The weights file of a pixel generator: one safetensors file with a hashed sidecar.

This module owns `save_pixel_generator` / `load_pixel_generator`. The file holds the
translator's (pix2pix) or the EMA U-Net's (DDPM) state dict, and in the safetensors header
one metadata entry, ``tacgen_pixel``: a JSON record (sorted keys) of the kind, settings, seed,
frame size, best step and value, steps run, early stop and the training curve. The bytes
depend only on the fit (safetensors orders tensors by dtype and name; one metadata key, so
no map order enters), and are written through `hashed.write_bytes` (atomic, sidecar first).

Only the pix2pix translator is kept, not its discriminator: generating needs G alone.
`ddpm` (and with it diffusers) is imported only when a DDPM file is read or written.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd
import torch
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors

from tacgen_lib.generate.pixel.pix2pix import Pix2PixFit, UNetTranslator
from tacgen_lib.generate.pixel.settings import Pix2PixSettings, PixelDDPMSettings
from tacgen_lib.io import hashed

if TYPE_CHECKING:
    from tacgen_lib.generate.pixel.ddpm import PixelDDPMFit

__all__ = ["KINDS", "load_pixel_generator", "save_pixel_generator"]

#: The generator kinds a weights file can hold.
KINDS = ("pix2pix", "ddpm")
#: The safetensors metadata key holding the JSON record of the fit.
_META_KEY = "tacgen_pixel"


def _describe(fit: Pix2PixFit | PixelDDPMFit, kind: str) -> str:
    s, (h, w) = fit.settings, fit.size
    if kind == "pix2pix":
        return f"pix2pix U-Net 3 -> {list(s.channels)} -> 3 channels, {h}x{w} frames"
    return (
        f"DDPM UNet2DModel 3+3 -> {list(s.channels)} x {s.layers_per_block} -> 3 channels "
        f"({s.prediction}-prediction, {s.schedule} T={s.train_steps}), {h}x{w} frames"
    )


def _check_kind(fit: object, kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    if kind == "pix2pix":
        ok = isinstance(fit, Pix2PixFit)
    else:
        from tacgen_lib.generate.pixel.ddpm import PixelDDPMFit

        ok = isinstance(fit, PixelDDPMFit)
    if not ok:
        raise ValueError(f"kind {kind!r} does not match the fit, a {type(fit).__name__}")


def save_pixel_generator(
    fit: Pix2PixFit | PixelDDPMFit,
    path: str | os.PathLike[str],
    *,
    kind: str,
    producer: str = "",
) -> str:
    """Write the fit's model weights and record as safetensors bytes, atomically with a
    sidecar hash (`hashed.write_bytes`); the same fit gives the same bytes. Returns SHA-256."""
    _check_kind(fit, kind)
    state = {k: v.detach().contiguous() for k, v in fit.model.state_dict().items()}
    record = {
        "kind": kind,
        "settings": dataclasses.asdict(fit.settings),
        "seed": int(fit.seed),
        "size": [int(fit.size[0]), int(fit.size[1])],
        "best_step": int(fit.best_step),
        "best_val": float(fit.best_val),
        "steps_run": int(fit.steps_run),
        "stopped_early": bool(fit.stopped_early),
        "scale": float(getattr(fit, "scale", 1.0)),
        "curve": {
            "columns": [str(c) for c in fit.curve.columns],
            "data": {str(c): fit.curve[c].tolist() for c in fit.curve.columns},
        },
    }
    data = save_tensors(state, metadata={_META_KEY: json.dumps(record, sort_keys=True)})
    return hashed.write_bytes(
        path,
        data,
        rows=1,
        key="generator",
        columns={"generator": _describe(fit, kind)},
        vectors={},
        producer=producer,
    )


def _record(data: bytes, path: Path) -> dict[str, Any]:
    """The JSON record in the safetensors header (8-byte little-endian length, then JSON)."""
    try:
        n = int.from_bytes(data[:8], "little")
        header = json.loads(data[8 : 8 + n])
        return json.loads(header["__metadata__"][_META_KEY])
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(
            f"{path}: not a pixel generator file (no {_META_KEY!r} record in its safetensors "
            f"header: {exc}); rewrite it with save_pixel_generator"
        ) from exc


def load_pixel_generator(
    path: str | os.PathLike[str], *, verify: bool = True
) -> Pix2PixFit | PixelDDPMFit:
    """A generator written by `save_pixel_generator` (its hash checked first), its model in
    eval mode. Refuses (ValueError naming the file and the keys) a file whose tensors are not
    exactly the model's state dict. The caller's global torch RNG is left as it was."""
    path = Path(path)
    if verify:
        hashed.verify(path)
    data = path.read_bytes()
    rec = _record(data, path)
    kind = rec.get("kind")
    size = (int(rec["size"][0]), int(rec["size"][1]))
    with torch.random.fork_rng(devices=[]):  # building a module draws initial weights
        if kind == "pix2pix":
            settings: Pix2PixSettings | PixelDDPMSettings = Pix2PixSettings.from_config(
                rec["settings"]
            )
            model = UNetTranslator(settings.channels, settings.dropout)
        elif kind == "ddpm":
            from tacgen_lib.generate.pixel.ddpm import make_unet

            settings = PixelDDPMSettings.from_config(rec["settings"])
            model = make_unet(settings, size)
        else:
            raise ValueError(f"{path}: unknown generator kind {kind!r} (known: {KINDS})")
    tensors = load_tensors(data)
    want, got = set(model.state_dict()), set(tensors)
    if want != got:
        missing, extra = sorted(want - got), sorted(got - want)
        raise ValueError(
            f"{path}: the {kind} weights do not match its settings: missing keys {missing}, "
            f"unexpected keys {extra}; rewrite the file with save_pixel_generator"
        )
    try:
        model.load_state_dict(tensors)
    except RuntimeError as exc:
        raise ValueError(f"{path}: the {kind} weights do not fit the model: {exc}") from exc
    model.eval()
    fields = {
        "model": model,
        "settings": settings,
        "seed": int(rec["seed"]),
        "size": size,
        "curve": pd.DataFrame(rec["curve"]["data"], columns=rec["curve"]["columns"]),
        "best_step": int(rec["best_step"]),
        "best_val": float(rec["best_val"]),
        "steps_run": int(rec["steps_run"]),
        "stopped_early": bool(rec["stopped_early"]),
    }
    if kind == "pix2pix":
        return Pix2PixFit(**fields)
    from tacgen_lib.generate.pixel.ddpm import PixelDDPMFit

    return PixelDDPMFit(**fields, scale=float(rec["scale"]))
