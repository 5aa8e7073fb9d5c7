"""Reading and writing the weights of the DINOv2-architecture ViT (`tacgen_lib.features.vit`):
official-format checkpoints (`dinov2_vit*14*_pretrain.pth`, training checkpoints with a
teacher / student wrapper or `backbone.` / `module.` prefixes) unwrapped to a bare state dict
(`unwrap_state_dict`), loaded without unpickling code (`load_tensors`), fitted to a model key
for key and shape for shape (`state_dict_mismatch`, `fit_pos_embed`, `load_pretrained`), a
backbone rebuilt from a checkpoint alone (`load_backbone`) and written atomically
(`save_backbone`).
"""

from __future__ import annotations

import argparse
import math
import pickle
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from tacgen_lib.features.archs import ARCHS
from tacgen_lib.features.vit import DinoVisionTransformer, build_vit, interpolate_pos_embed

__all__ = [
    "fit_pos_embed",
    "load_backbone",
    "load_pretrained",
    "load_tensors",
    "save_backbone",
    "state_dict_mismatch",
    "unwrap_state_dict",
]

_WRAPPER_KEYS = ("teacher", "model", "state_dict", "student")
_PREFIXES = ("module.", "backbone.")


def unwrap_state_dict(obj: object, *, where: str = "checkpoint") -> dict[str, Tensor]:
    """Bare backbone state dict from an official-format checkpoint object.

    Accepted forms: a flat {name: tensor} dict (the official `*_pretrain.pth`); or a dict with
    one of "teacher", "model", "state_dict", "student" (tried in that order; teacher first, as
    DINO evaluates the teacher) holding such a dict. Then, if any key starts with "backbone."
    (DINOv2 training checkpoints), only those keys are kept (heads such as dino_head.* / ibot_head.*
    are dropped); "module." (DDP) and "backbone." prefixes are stripped.
    """
    if not isinstance(obj, Mapping):
        raise TypeError(f"{where}: expected a dict of tensors, got {type(obj).__name__}")
    for key in _WRAPPER_KEYS:
        if key in obj and isinstance(obj[key], Mapping):
            obj = obj[key]
            break
    sd = {str(k): v for k, v in obj.items()}
    for prefix in _PREFIXES:
        if any(k.startswith(prefix) for k in sd):
            if prefix == "backbone.":
                sd = {k: v for k, v in sd.items() if k.startswith(prefix)}
            sd = {k.removeprefix(prefix): v for k, v in sd.items()}
    bad = [k for k, v in sd.items() if not isinstance(v, Tensor)]
    if bad:
        raise TypeError(f"{where}: entries are not tensors: {bad[:10]}")
    return sd


def load_tensors(path: str | Path) -> Any:
    """`torch.load` with ``weights_only=True``: tensors and plain containers only, plus
    `argparse.Namespace`, the ``args`` entry MAE's training code saves beside its ``model``
    (its `misc.save_model`: model, optimizer, epoch, scaler, args), which holds plain values.

    A checkpoint that needs other objects (a crafted pickle could run code when unpickled)
    is refused with a ValueError naming the file; nothing in it is executed.
    """
    try:
        with torch.serialization.safe_globals([argparse.Namespace]):
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(
            f"{path}: not a tensor state dict; refused to unpickle it (weights_only=True: only "
            f"tensors and plain containers are loaded, no code is run): {first}"
        ) from exc


def state_dict_mismatch(own: Mapping[str, Tensor], sd: Mapping[str, Tensor]) -> str:
    """ "" when a checkpoint's state dict `sd` fits a model's `own` key for key and shape for
    shape; else one sentence listing every missing, unexpected and shape-mismatched key (the
    loaders of every backbone family raise it, naming the file)."""
    missing = sorted(set(own) - set(sd))
    unexpected = sorted(set(sd) - set(own))
    mismatched = sorted(
        f"{k}: checkpoint {tuple(sd[k].shape)} vs model {tuple(own[k].shape)}"
        for k in set(own) & set(sd)
        if sd[k].shape != own[k].shape
    )
    return "; ".join(
        f"{what} ({len(keys)}): {keys}"
        for what, keys in (
            ("missing keys", missing),
            ("unexpected keys", unexpected),
            ("shape mismatches", mismatched),
        )
        if keys
    )


def fit_pos_embed(
    sd: dict[str, Tensor], model: DinoVisionTransformer, *, offset: float, antialias: bool
) -> None:
    """Resize a checkpoint's square `pos_embed` grid (in `sd`, in place) bicubically to the
    model's grid when the widths agree and the grids differ, as the checkpoint's own code
    resamples it (`interpolate_pos_embed` with that code's `offset` and `antialias`).

    A DINOv2 checkpoint keeps its 37 x 37 grid and resamples it at every forward to the input's
    grid with its model's `interpolate_offset` and `interpolate_antialias` (0.1 and off for the
    plain models, 0 and on for the register ones: `vit.build_vit`); resampling once here with
    the same two settings gives the same position embeddings, so the features at the model's
    input size are DINOv2's own. MAE resizes to an exact size, without antialiasing
    (`mae.load_mae_checkpoint`).
    """
    own = model.state_dict()["pos_embed"]
    pe = sd.get("pos_embed")
    if pe is not None and pe.ndim == 3 and pe.shape != own.shape:
        if pe.shape[-1] == own.shape[-1] and math.isqrt(pe.shape[1] - 1) ** 2 == (pe.shape[1] - 1):
            g = model.grid_size
            patch = interpolate_pos_embed(pe[:, 1:], (g, g), offset=offset, antialias=antialias)
            sd["pos_embed"] = torch.cat((pe[:, :1].float(), patch), dim=1).to(pe.dtype)


def load_pretrained(model: DinoVisionTransformer, path: str | Path) -> DinoVisionTransformer:
    """Load an official-format DINOv2 checkpoint into `model` (in place; also returned).

    See `unwrap_state_dict` for the accepted wrappers/prefixes. `pos_embed` is resized to the
    model's grid when the grids differ, as DINOv2 resamples it at the model's input size (the
    model's own `interpolate_offset` and `interpolate_antialias`: `fit_pos_embed`). Any missing,
    unexpected or shape-mismatched key is refused with a ValueError listing them all.
    """
    path = Path(path)
    raw = load_tensors(path)
    sd = unwrap_state_dict(raw, where=str(path))
    own = model.state_dict()

    fit_pos_embed(sd, model, offset=model.interpolate_offset, antialias=model.interpolate_antialias)
    problems = state_dict_mismatch(own, sd)
    if problems:
        raise ValueError(
            f"{path}: checkpoint does not fit the model "
            f"(embed_dim {model.embed_dim}, depth {len(model.blocks)}, "
            f"registers {model.num_register_tokens}); {problems}. "
            "Build the matching arch (see tacgen_lib.features.archs.ARCHS) or use load_backbone(path)."
        )
    model.load_state_dict({k: v.to(own[k].dtype) for k, v in sd.items()}, strict=True)
    return model


def save_backbone(model: DinoVisionTransformer, path: str | Path) -> None:
    """Write the model's weights as a flat official-format state dict (atomic: temp + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save({k: v.detach().clone().contiguous() for k, v in model.state_dict().items()}, tmp)
    tmp.replace(path)


def load_backbone(path: str | Path) -> DinoVisionTransformer:
    """Build the architecture a checkpoint describes, then `load_pretrained` it.

    Width comes from cls_token, depth from the blocks.{i} keys, the pos_embed grid from
    pos_embed, registers from register_tokens; heads from the ARCHS entry with that width and
    depth (heads cannot be read from shapes).
    """
    path = Path(path)
    sd = unwrap_state_dict(load_tensors(path), where=str(path))
    if "cls_token" not in sd or "pos_embed" not in sd:
        raise ValueError(f"{path}: no cls_token/pos_embed; not a DINOv2-format ViT checkpoint")
    dim = int(sd["cls_token"].shape[-1])
    depth = 1 + max(int(k.split(".")[1]) for k in sd if k.startswith("blocks."))
    patch = int(sd["patch_embed.proj.weight"].shape[-1]) if "patch_embed.proj.weight" in sd else 0
    matches = [
        a
        for a, c in ARCHS.items()
        if c.embed_dim == dim and c.depth == depth and c.patch_size == patch
    ]
    if not matches:
        raise ValueError(
            f"{path}: no known arch with embed_dim {dim}, depth {depth} and patch {patch}; known: "
            + ", ".join(
                f"{a} ({c.embed_dim}d/{c.depth}L/p{c.patch_size})" for a, c in ARCHS.items()
            )
        )
    grid = math.isqrt(sd["pos_embed"].shape[1] - 1)
    regs = int(sd["register_tokens"].shape[1]) if "register_tokens" in sd else 0
    model = build_vit(matches[0], img_size=grid * patch, num_register_tokens=regs)
    return load_pretrained(model, path)
