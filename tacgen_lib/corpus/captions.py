"""The caption vocabulary the paper uses for real data: adjective lists parsed from a caption,
the hard/soft label they imply, and the top-k adjective-pattern strata SSVTP splits are
stratified by.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable, Sequence

OTHER_STRATUM = "other"


def parse_caption(text: str) -> list[str]:
    """Adjectives of a TVL caption: comma (or line) separated, normalised, in order.

    Each piece is lower-cased, inner whitespace is collapsed, surrounding spaces and periods are
    dropped (TVL removes periods too), empty pieces (trailing commas) are skipped and repeats
    keep their first position. ``"Smooth,  HARD, smooth., "`` gives ``["smooth", "hard"]``.
    """
    adjectives: list[str] = []
    seen: set[str] = set()
    for piece in re.split(r"[,\n\r]", text):
        adjective = " ".join(piece.split()).strip(". ").lower()
        if adjective and adjective not in seen:
            seen.add(adjective)
            adjectives.append(adjective)
    return adjectives


def hardness_from_adjectives(adjs: Iterable[str]) -> str | None:
    """Binary hardness label of a caption: "hard", "soft" or None.

    Exact adjective match after normalisation ("hard", not "hardened"). A caption with both
    "hard" and "soft" is contradictory and one with neither says nothing: both give None, so
    such samples carry no hardness label rather than a guessed one.
    """
    words = {" ".join(a.split()).strip(". ").lower() for a in adjs}
    hard, soft = "hard" in words, "soft" in words
    if hard and not soft:
        return "hard"
    if soft and not hard:
        return "soft"
    return None


def adjective_pattern(adjs: Sequence[str]) -> str:
    """The pattern of an adjective list: its distinct adjectives, sorted, joined by "+"."""
    return "+".join(sorted(set(adjs)))


def top_pattern_strata(adjective_lists: Sequence[Sequence[str]], k: int = 5) -> list[str]:
    """Stratum of every sample: its adjective pattern if among the k most frequent, else "other".

    The paper stratifies SSVTP splits by the top-5 adjective patterns. Patterns are ranked by
    count (descending), ties broken by pattern name (ascending), so the result does not depend
    on row order. Returns one stratum per input list, in input order.
    """
    if k < 0:
        raise ValueError(f"top_pattern_strata: k must be >= 0, got {k}")
    patterns: list[str] = []
    for position, adjs in enumerate(adjective_lists):
        if isinstance(adjs, str):
            raise TypeError(
                f"top_pattern_strata: item {position} is a string ({adjs!r}); "
                "pass lists of adjectives (see parse_caption)"
            )
        if len(adjs) == 0:
            raise ValueError(
                f"top_pattern_strata: adjective list at position {position} is empty; "
                "every sample needs at least one adjective to have a pattern"
            )
        patterns.append(adjective_pattern(adjs))
    ranked = sorted(Counter(patterns).items(), key=lambda item: (-item[1], item[0]))
    top = {pattern for pattern, _ in ranked[:k]}
    return [p if p in top else OTHER_STRATUM for p in patterns]
