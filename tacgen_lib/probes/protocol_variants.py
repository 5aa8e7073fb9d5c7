"""Probe protocol variants: which probe a comparison fits (the ``{protocol}`` wildcard).

A reader should see which V vs V+T results survive a reasonable change of protocol. Each
variant is a name in `PROTOCOLS`, threaded through `settings.ProbeSettings` into
`fit.fit_probe`, so every variant runs the same family code (rows, comparisons,
bootstrap, controls, criterion):

- ``raw``: the paper's probes, unchanged (ridge on raw features; logistic with its scaler).
- ``standardised``: per-feature ``StandardScaler`` fitted on the training rows of each fit,
  then the same ridge (`scaling`); the logistic probes already standardise inside every fit,
  so for them ``standardised`` IS ``raw`` (`same_as_raw`): the workflow does not recompute
  it and the robustness table says so.
- ``mlp2``: a 2-layer probe, width and weight decay by CV on the training rows, seeded (`mlp`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PROTOCOLS", "Protocol", "check_protocol", "same_as_raw"]


@dataclass(frozen=True)
class Protocol:
    name: str
    description: str
    same_as_raw_for: tuple[str, ...] = ()  # probe kinds for which this variant equals raw


PROTOCOLS: dict[str, Protocol] = {
    p.name: p
    for p in [
        Protocol("raw", "the paper's probes: ridge on raw features, logistic on standardised"),
        Protocol(
            "standardised",
            "StandardScaler fitted on each fit's training rows, then the same ridge / logistic",
            same_as_raw_for=("logistic",),
        ),
        Protocol(
            "mlp2",
            "2-layer MLP (one hidden ReLU layer) on standardised features, width and weight "
            "decay by CV on training rows, seeded",
        ),
    ]
}


def check_protocol(name: str) -> str:
    if name not in PROTOCOLS:
        raise ValueError(f"probe protocol {name!r}: choose one of {sorted(PROTOCOLS)}")
    return name


def same_as_raw(protocol: str, kind: str) -> bool:
    """Whether `protocol` fits exactly the raw probe for a family of this kind."""
    return protocol != "raw" and kind in PROTOCOLS[check_protocol(protocol)].same_as_raw_for
