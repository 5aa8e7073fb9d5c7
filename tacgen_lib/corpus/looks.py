"""What a simulated frame shows: the vocabulary of looks (colours, textures, size words), the
visible factors of each sample and its look.

A simulated sample's caption adjectives (`corpus.sim.corpus`) are, in order, its size word,
colour, texture, hardness and weight; its manifest row also carries its shape and, on the
natural design, its appearance class (``appearance_id``: (colour index + texture index) mod 6).
The first three adjectives and the shape are what the RGB frame shows; hardness and weight are
not. This module reads them back by vocabulary, never by position alone, so a caption that
does not hold one of them is refused, naming the sample.

- `visible_factors`: sample_id -> colour, texture, shape, size (and ``appearance`` where the
  corpus has an appearance class): the labels of the visibility check
  (`tacgen_lib.generate.visibility`);
- `look_keys`: sample_id -> the sample's look, colour|texture|shape|size, the key the look
  oracle of the regime's generator ladder (`tacgen_lib.generate.ladder.look_oracle`) averages
  real touch over.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = [
    "FACTORS",
    "PALETTE",
    "TEXTURE_WORDS",
    "LOOK_FACTORS",
    "LOOK_LEVELS",
    "SIZE_WORDS",
    "look_keys",
    "look_levels",
    "visible_factors",
]

#: An object's colour word -> its RGB (before the natural design's per-channel jitter).
#: A texture darkens the colour it is drawn on (a MuJoCo texture multiplies the material's
#: rgba; `scenes.texture_faces`), so the darkest colour sets how much texture a frame can show:
#: "black" is a charcoal, about as dark as red, whose checks, stripes and speckles still differ
#: from the ground by tens of grey levels. At a near-black they differed by a few, and
#: black was the one colour whose texture even a classifier trained on the texture labels
#: could not read, so no vision side could see the appearance class of a black object.
PALETTE: dict[str, tuple[float, float, float]] = {
    "red": (0.85, 0.15, 0.12),
    "orange": (0.95, 0.55, 0.1),
    "yellow": (0.95, 0.88, 0.2),
    "green": (0.2, 0.7, 0.25),
    "blue": (0.15, 0.35, 0.9),
    "purple": (0.55, 0.25, 0.75),
    "white": (0.92, 0.92, 0.9),
    "black": (0.26, 0.26, 0.28),
}

#: An object's texture (the scene's material name) -> its caption word.
TEXTURE_WORDS = {
    "plain": "plain",
    "checkered": "checkered",
    "striped": "striped",
    "speckled": "speckled",
}

#: The size words of a simulated caption (the object's size in thirds of the corpus's range).
SIZE_WORDS = ("small", "medium-sized", "large")

#: The visible factors of a simulated frame, in the order the report lists them.
FACTORS = ("colour", "texture", "shape", "size", "appearance")

#: The factors that make a look (the appearance class is a function of colour and texture).
LOOK_FACTORS = ("colour", "texture", "shape", "size")

#: A look and its coarser back-offs: without size, then colour and texture alone (what sets
#: the natural design's appearance class).
LOOK_LEVELS = (LOOK_FACTORS, ("colour", "texture", "shape"), ("colour", "texture"))


def visible_factors(manifest: pd.DataFrame, *, appearance_class: bool = False) -> pd.DataFrame:
    """The visible factors of every row of a simulated corpus's manifest rows.

    manifest: rows with ``sample_id``, ``adjectives`` (a sequence of words), ``shape`` and,
    with `appearance_class` (the natural design, whose ``appearance_id`` is the appearance
    class; on the other designs it indexes objects), ``appearance_id``. Returns a frame indexed
    by sample_id with string columns colour, texture, shape, size and, with
    `appearance_class`, appearance. Raises ValueError naming the first sample whose adjectives
    hold no colour, texture or size word of the simulator's vocabulary.
    """
    colours, textures = frozenset(PALETTE), frozenset(TEXTURE_WORDS.values())
    sizes = frozenset(SIZE_WORDS)

    def pick(words, vocab: frozenset[str], what: str, sample: str) -> str:
        found = [w for w in words if w in vocab]
        if len(found) != 1:
            raise ValueError(
                f"visible_factors: sample_id {sample!r} has adjectives {list(words)!r}: "
                f"expected exactly one {what} word of {sorted(vocab)}"
            )
        return found[0]

    out = {"colour": [], "texture": [], "size": []}
    ids = manifest["sample_id"].astype(str).to_numpy()
    for sample, words in zip(ids, manifest["adjectives"], strict=True):
        words = [str(w) for w in (words if words is not None else [])]
        out["colour"].append(pick(words, colours, "colour", sample))
        out["texture"].append(pick(words, textures, "texture", sample))
        out["size"].append(pick(words, sizes, "size", sample))
    frame = pd.DataFrame(
        {
            "colour": out["colour"],
            "texture": out["texture"],
            "shape": manifest["shape"].astype(str).to_numpy(),
            "size": out["size"],
        },
        index=pd.Index(ids, name="sample_id"),
    )
    if appearance_class:
        frame["appearance"] = manifest["appearance_id"].to_numpy(dtype=np.int64).astype(str)
    return frame


def look_keys(factors: pd.DataFrame, names: tuple[str, ...] = LOOK_FACTORS) -> pd.Series:
    """sample_id -> its look, ``colour|texture|shape|size`` (`LOOK_FACTORS`, or the factors
    `names`), from `visible_factors`' frame: two samples with one key look alike up to colour
    jitter, pose and size within a third of the range."""
    missing = [f for f in names if f not in factors]
    if missing:
        raise ValueError(f"look_keys: factors frame lacks {missing}")
    keys = factors[list(names)].astype(str).agg("|".join, axis=1)
    return keys.rename("look")


def look_levels(factors: pd.DataFrame) -> list[pd.Series]:
    """The look keys of every level of `LOOK_LEVELS`, finest first (the look oracle's back-off,
    `generate.ladder.look_oracle`)."""
    return [look_keys(factors, names) for names in LOOK_LEVELS]
