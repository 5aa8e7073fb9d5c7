"""What the library reads of a corpus's declaration (`corpora.<name>`) without the simulator:
the labels result rows carry (`corpus_labels`) and the cross-key rules of a simulated corpus,
what a JSON schema cannot say. Shared by `CorpusSettings` (tacgen_lib.corpus.sim.samples) and the config's
validation before any job runs (tacgen_lib.workflow_config), without importing the simulator."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["corpus_key_errors", "corpus_labels"]


def corpus_key_errors(corpus: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(key, message) for each cross-key rule `corpus` (one simulated `corpora.<name>` mapping,
    its defaults filled: `workflow_config.validate_config`) breaks: rho belongs to design
    natural, contacts > 1 to design paired, and n must be a whole number of objects of
    `contacts` contacts each."""
    design = corpus["design"]
    rho, contacts, n = corpus["rho"], int(corpus["contacts"]), int(corpus["n"])
    out = []
    if rho and design != "natural":
        out.append(("rho", f"key 'rho' belongs to design 'natural', not {design!r}"))
    if contacts > 1 and design != "paired":
        out.append(("contacts", f"key 'contacts' belongs to design 'paired', not {design!r}"))
    if contacts >= 1 and n % contacts:
        out.append(("n", f"n={n} is not a whole number of objects of {contacts} contacts each"))
    return out


def corpus_labels(corpus: Mapping[str, Any]) -> dict[str, Any]:
    """The labels every result row of a corpus carries, from its declaration: ``design`` (a
    simulated corpus's design, an ingested corpus's kind) and ``null_corpus`` (its touch
    carries no information about its frames)."""
    return {
        "design": corpus.get("design", corpus["kind"]),
        # a real corpus has no key null: its touch is its own
        "null_corpus": corpus["kind"] == "simulated" and bool(corpus["null"]),
    }
