"""Every stage's plan, built once from the validated config in the order the stages depend on
one another (each checks its part of the config as it is built)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from tacgen_lib.plan.align import AlignPlan
from tacgen_lib.plan.families import FamiliesPlan
from tacgen_lib.plan.features import FeaturesPlan
from tacgen_lib.plan.generate import GeneratePlan
from tacgen_lib.plan.pixel import PixelPlan
from tacgen_lib.plan.policy import PolicyPlan
from tacgen_lib.plan.probes import ProbesPlan
from tacgen_lib.plan.regime import RegimePlan
from tacgen_lib.plan.transfer import TransferPlan


@dataclass(frozen=True)
class StagePlans:
    """The plans of the stages the rules expand (rules/*.smk)."""

    features: FeaturesPlan
    align: AlignPlan
    generate: GeneratePlan
    regime: RegimePlan
    pixel: PixelPlan
    probes: ProbesPlan
    families: FamiliesPlan
    transfer: TransferPlan
    policy: PolicyPlan

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> StagePlans:
        features = FeaturesPlan.from_config(config)
        align = AlignPlan.from_config(config)
        generate = GeneratePlan.from_config(config)
        regime = RegimePlan.from_config(config)
        pixel = PixelPlan.from_config(config)
        probes = ProbesPlan.from_config(config, align)
        families = FamiliesPlan.from_config(config, features, probes.jobs)
        transfer = TransferPlan.from_config(config, align)
        policy = PolicyPlan.from_config(config)
        return cls(features, align, generate, regime, pixel, probes, families, transfer, policy)
