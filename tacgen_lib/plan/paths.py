"""Path families and wildcard patterns every stage's rules share: corpus and feature edges, the
frames a backbone reads, benchmark files, and the constraints that match a set of names."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path

from tacgen_lib.io.imports import code_inputs

#: a regex matching no name (the constraint of a rule with no corpus of its kind)
MATCHES_NOTHING = "(?!x)x"


def one_of(names: Iterable[str]) -> str:
    """Wildcard constraint accepting exactly these names."""
    names = list(names)
    return "|".join(map(re.escape, names)) if names else MATCHES_NOTHING


def none_of(names: Iterable[str]) -> str:
    """Wildcard constraint accepting any path segment except these names (no ruleorder: a
    ruleorder breaks the cost sweep's modules that import only one of its rules)."""
    return f"(?!(?:{one_of(names)})(?![^/]))[^/]+"


def corpus_edge(corpus: str, what: str = "samples") -> str:
    """A corpus's edge: its samples (frames and labels) or its sensors (backgrounds)."""
    return f"results/corpus/{corpus}/{what}.parquet"


def preprocessed_frames(corpus: str, variant: str) -> str:
    """A corpus's tactile frames after one preprocessing variant (rule background_subtract)."""
    return f"results/preprocess/{corpus}/{variant}.parquet"


def feature_edge(corpus: str, modality: str, variant: str | None = None) -> str:
    """The frozen-feature edge of a corpus: vision, or tactile for one preprocessing variant."""
    if modality == "vision":
        return f"results/features/{corpus}/vision.parquet"
    return f"results/features/{corpus}/tactile~{variant}.parquet"


def benchmark_file(rule: str, job: str) -> str:
    """The benchmark file of one job of `rule` (`job`: its wildcards' part of the path), as its
    `benchmark:` directive writes it and every reader of its seconds reads it."""
    return f"results/benchmarks/{rule}/{job}.tsv"


def script_imports(workflow_root: str | os.PathLike[str], script: str) -> list[str]:
    """Code inputs of a rule: the tacgen_lib modules its script reaches through imports.

    Derived from the script's source (tacgen_lib.io.imports), so editing a module reruns exactly
    the jobs whose scripts reach it, however indirectly.
    """
    base = Path(workflow_root)
    return code_inputs(base / "workflow" / "scripts" / f"{script}.py", base / "tacgen_lib")
