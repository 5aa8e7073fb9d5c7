"""Saving and loading trained heads: `save_heads` / `load_heads` (torch.save with deterministic
content, hashed like an edge: a `<file>.sha256.json` sidecar, verified on load; only tensors are
unpickled).
"""

from __future__ import annotations

import io
import os
from typing import Any

import torch

from tacgen_lib.align.heads import AlignHeads, AlignResult, heads_from_state
from tacgen_lib.io import hashed

_FORMAT = "tacgen-align-heads/1"


def heads_payload(result: AlignResult) -> dict[str, Any]:
    """What `save_heads` serialises: format, dims, config, curve and both heads' weights."""
    return {
        "format": _FORMAT,
        "dims": dict(result.dims),
        "config": dict(result.config),
        "best_step": int(result.best_step),
        "best_val_loss": float(result.best_val_loss),
        "steps_run": int(result.steps_run),
        "total_steps": int(result.total_steps),
        "stopped_early": bool(result.stopped_early),
        "curve": [dict(c) for c in result.curve],
        "vision": result.heads["vision"],
        "tactile": result.heads["tactile"],
    }


def save_heads(result: AlignResult, path: str | os.PathLike[str], *, producer: str = "") -> str:
    """Write the best heads, dims, config and curve with torch.save, atomically; returns SHA-256.

    The content is deterministic: wall-clock seconds are not stored and the bytes are
    serialised in memory (so the zip's internal folder name does not depend on a temp file
    name) before a temp-file + rename. Same fit => same file bytes.
    Like an edge, the file gets a `<file>.sha256.json` sidecar (written first, see
    `tacgen_lib.io.edges`) naming its hash, the two heads' shapes and the producing rule, so the
    report's edge manifest lists it and `load_heads` refuses a file changed after it was written.
    """
    buf = io.BytesIO()
    torch.save(heads_payload(result), buf)
    data = buf.getvalue()
    dims = result.dims
    layers = f"{dims['hidden_dim']}->{dims['out_dim']}"
    return hashed.write_bytes(
        path,
        data,
        rows=2,
        key="head",
        columns={
            "vision": f"mlp {dims['in_dim_v']}->{layers}",
            "tactile": f"mlp {dims['in_dim_t']}->{layers}",
        },
        vectors={},
        producer=producer,
    )


def load_heads(path: str | os.PathLike[str], *, verify: bool = True) -> AlignHeads:
    """Load heads written by `save_heads` as an `AlignHeads` module in eval mode.

    verify: check the file's SHA-256 against its sidecar first (`hashed.verify`).
    The stored metadata (config, curve, best_step...) is attached as ``heads.meta``.
    """
    if verify:
        hashed.verify(path)
    try:
        payload = torch.load(os.fspath(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - re-raised with the file named
        raise ValueError(f"{path}: not a readable heads file ({exc}); rerun train_heads") from exc
    if not isinstance(payload, dict) or payload.get("format") != _FORMAT:
        raise ValueError(f"{path}: not a {_FORMAT} file; rerun train_heads to regenerate it")
    heads = heads_from_state(payload["dims"], payload)
    heads.meta = {k: v for k, v in payload.items() if k not in ("vision", "tactile")}
    return heads
