"""The pixel generators' plan: their corpora, arms (pix2pix and the pixel DDPM's cells), seeds,
edges and benchmark files (rules/pixel.smk)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from tacgen_lib.generate.pixel.utility import GENERATORS, ddpm_arm
from tacgen_lib.plan.paths import benchmark_file

PIXEL_DIR = "results/pixel"
PIXEL_REPORT = "results/report/pixel"
PIXEL_GENERATOR = f"{PIXEL_DIR}/{{corpus}}/{{generator}}/seed~{{seed}}"
PIXEL_ARM = f"{PIXEL_DIR}/{{corpus}}/arms/{{arm}}/seed~{{seed}}/frames.parquet"
PIXEL_EVAL = f"{PIXEL_DIR}/{{corpus}}/seed~{{seed}}"
PIXEL_POINT = f"{PIXEL_DIR}/curve/{{corpus}}/seed~{{seed}}/p~{{fraction}}.parquet"
#: the pixel page's items and their kinds
PIXEL_ITEMS = {
    "architecture": "html",
    "calibration": "html",
    "curve": "png",
    "scatter": "png",
    **{f"filmstrip_{g}": "png" for g in GENERATORS},
}
#: a config without the section (one given with --replace-workflow-config) runs no pixel stage
NO_PIXEL = {"corpora": {}, "curve": {"corpora": {}}, "seeds": []}


def arm_generator_name(arm: str) -> str:
    """The generator an arm samples: pix2pix, or the pixel DDPM for each of its cells."""
    return "pix2pix" if arm == "pix2pix" else "ddpm"


def fraction_text(p: float | str) -> str:
    """A curve point's fraction as its path writes it."""
    return f"{float(p):g}"


@dataclass(frozen=True)
class PixelPlan:
    """config pixel, checked against the corpora, the splits and the probes' heads variant."""

    settings: Mapping[str, Any]

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> PixelPlan:
        plan = cls(config.get("pixel") or NO_PIXEL)
        for corpus in plan.train_corpora:
            if corpus not in config["corpora"]:
                raise ValueError(
                    f"config pixel: {corpus!r} is not a corpus (have {sorted(config['corpora'])})"
                )
            if corpus in config["splits"]["by_object"]:
                raise ValueError(
                    f"config pixel: corpus {corpus!r} is split by object; the pixel generators "
                    "need the random train/val/test split"
                )
        if plan.train_corpora and not plan.ddpm_arms:
            raise ValueError(
                "config pixel.ddpm_cells: needs at least one guidance and one steps value"
            )
        variant = config["probes"]["heads"]["variant"]
        if plan.curve_corpora and variant != "clip128":
            raise ValueError(
                "config pixel.curve: the generators imitate clip128 frames; probes.heads.variant "
                f"is {variant!r}"
            )
        return plan

    @cached_property
    def corpora(self) -> list[str]:
        """The corpora whose utility is judged."""
        return list(self.settings["corpora"])

    @cached_property
    def curve(self) -> Mapping[str, Any]:
        return self.settings["curve"]

    @cached_property
    def curve_corpora(self) -> list[str]:
        return list(self.curve["corpora"])

    @cached_property
    def train_corpora(self) -> list[str]:
        """Every corpus a pixel generator is trained on: the judged ones, then the curve's."""
        return self.corpora + [c for c in self.curve_corpora if c not in self.corpora]

    @cached_property
    def ddpm_arms(self) -> list[str]:
        """The DDIM cells of the pixel DDPM, as arm names (ddpm_w<w>_s<steps>)."""
        cells = self.settings.get("ddpm_cells") or {"guidance": []}
        return [ddpm_arm(w, s) for w in cells["guidance"] for s in cells["steps"]]

    @cached_property
    def judged_arms(self) -> list[str]:
        return ["pix2pix"] + self.ddpm_arms

    @cached_property
    def curve_arm(self) -> str | None:
        """The curve's generator: pix2pix, or the pixel DDPM's first cell (None: no curve)."""
        if not self.curve_corpora:
            return None
        return "pix2pix" if self.curve["generator"] == "pix2pix" else self.ddpm_arms[0]

    @cached_property
    def on(self) -> bool:
        """Whether the stage runs: a corpus to train on and a seed."""
        return bool(self.train_corpora and self.seeds())

    def arms(self, corpus: str) -> list[str]:
        """The arms sampled on a corpus: every judged arm where utility is judged, else the
        curve's."""
        return self.judged_arms if corpus in self.corpora else [self.curve_arm]

    def generators(self, corpus: str) -> list[str]:
        return sorted({arm_generator_name(a) for a in self.arms(corpus)})

    def seeds(self) -> list[str]:
        return [str(s) for s in self.settings["seeds"]]

    def arm_edge(self, corpus: str, arm: str, seed: str) -> str:
        return PIXEL_ARM.format(corpus=corpus, arm=arm, seed=seed)

    def arm_edges(self) -> list[str]:
        """Every arm's frames on every training corpus and seed."""
        return [
            self.arm_edge(c, a, s)
            for c in self.train_corpora
            for a in self.arms(c)
            for s in self.seeds()
        ]

    def eval_files(self, name: str) -> list[str]:
        """`name` of every judged corpus x seed."""
        return [
            f"{PIXEL_EVAL}/{name}".format(corpus=c, seed=s)
            for c in self.corpora
            for s in self.seeds()
        ]

    def points(self) -> list[str]:
        """Every curve point: corpus x seed x fraction."""
        return [
            PIXEL_POINT.format(corpus=c, seed=s, fraction=fraction_text(p))
            for c in self.curve_corpora
            for s in self.seeds()
            for p in self.curve["fractions"]
        ]

    def weights(self) -> list[str]:
        return [
            f"{PIXEL_GENERATOR}/generator.safetensors".format(corpus=c, generator=g, seed=s)
            for c in self.train_corpora
            for g in self.generators(c)
            for s in self.seeds()
        ]

    def benchmarks(self, rule_name: str) -> list[str]:
        """The benchmark files of one pixel rule (the page's seconds)."""
        if rule_name == "train_pixel_generator":
            jobs = [
                f"{c}/{g}/{s}"
                for c in self.train_corpora
                for g in self.generators(c)
                for s in self.seeds()
            ]
        else:
            jobs = [
                f"{c}/{a}/{s}"
                for c in self.train_corpora
                for a in self.arms(c)
                for s in self.seeds()
            ]
        return [benchmark_file(rule_name, j) for j in jobs]
