"""The samples of a simulated corpus before simulation: a corpus's settings
(`CorpusSettings`) and everything drawn for each of its samples (`sample_spec`: shape, size,
physics, look, sensor, press jitter), which `tacgen_lib.corpus.sim.corpus` then presses and
renders.

A corpus config (config/config.yaml `corpora.<name>`, plus `name`) has the keys

    name, kind: simulated, design: paired | controlled | natural, n, seed, scene,
    rho (natural: the appearance-material link, default 0), null (bool, default
    false), sensors (default 4), presses (default 8), image_size [H, W] (default [224, 224]),
    tactile_size [H, W] (default [120, 160]), shapes (optional subset of the scene's shapes),
    size_range [min, max] (paired: object size in m, default [0.02, 0.04]),
    scales (controlled: default [0.15, 0.20, 0.25]), size_per_scale (controlled: metres of
    object size per unit of scale, default 0.15, so scale 0.20 -> 3 cm),
    densities (default [500, 2000, 5000] kg/m^3), png_compression (default 1),
    contacts (paired: samples per object, default 1);
    other keys (e.g. `shards`, used by the workflow) are ignored.

Everything about sample i is drawn from `scene_seed(seed, i)` only, in five independent
streams (geometry, physics, appearance, jitter, pixels), so shards can run in parallel and
concatenate to the same corpus for any n_shards. In the paired and controlled designs
appearance (colour, texture, yaw) never depends on physics (density, hardness, friction): the
RGB frame is rendered in the presentation pose (object resting on the undeformed gel), before
any press.

The natural design links them as real objects are linked, imperfectly: each object is of a
material class (`MATERIALS`: class-level density, contact stiffness range, hence hardness,
and friction, each with within-class spread), and shows the textures and colours of an
*appearance class* that is its material with probability ``rho`` and uniform over the classes
otherwise (`appearance_class`). An appearance class is a family of (colour, texture) pairs,
class = (colour index + texture index) mod 6 (`APPEARANCE_FAMILIES`): every texture and most
colours occur in several classes, so neither decodes the class alone, and the colour is
jittered per object (lighting, dye). rho = 0 reproduces the independence of the paired design;
rho = 1 makes appearance a (nonlinear) function of material. The physics of sample i does not
depend on rho: a rho grid changes only what the objects look like.

Repeated contacts (YCB-Sight-like transfer corpora): with ``contacts`` = c > 1 (paired design),
samples i = o * c + k for k < c are c contacts with object o. The object's geometry, physics
and appearance come from object o's scene seed, each contact's presses, sensor and pixel noise
from its own sample seed; ``appearance_id`` is the object index o, which object-level splits
group on. With c = 1 every draw is the one above (the object index is the sample index).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from tacgen_lib.corpus.derangement import sattolo_cycle
from tacgen_lib.corpus.keys import corpus_key_errors
from tacgen_lib.corpus.looks import PALETTE, TEXTURE_WORDS
from tacgen_lib.corpus.sim import physics
from tacgen_lib.corpus.sim.scenes import Scene
from tacgen_lib.io.config import settings_from
from tacgen_lib.io.schema import SchemaSettings, not_config, schema_fields

SOFT_RANGE = (600.0, 2000.0)  # N/m, contact stiffness of soft objects (log-uniform)


HARD_RANGE = (8000.0, 25000.0)  # N/m, hard objects


FRICTION_RANGE = (0.3, 1.2)


@dataclass(frozen=True)
class Material:
    """A material class of the natural design: density (kg/m^3, the class mean; objects
    spread log-normally around it), contact stiffness range (N/m, log-uniform; it sets the
    hardness class), friction (the class mean; objects spread uniformly around it)."""

    name: str
    density: float
    stiffness: tuple[float, float]
    friction: float

    @property
    def hardness(self) -> str:
        return "soft" if self.stiffness[1] <= SOFT_RANGE[1] else "hard"


#: The natural design's material classes (their order is the appearance-class index).
MATERIALS: tuple[Material, ...] = (
    Material("foam", 300.0, (600.0, 1200.0), 0.9),
    Material("rubber", 1100.0, (1200.0, 2000.0), 1.1),
    Material("wood", 650.0, (8000.0, 12000.0), 0.5),
    Material("plastic", 1200.0, (10000.0, 16000.0), 0.4),
    Material("ceramic", 2400.0, (16000.0, 25000.0), 0.6),
    Material("metal", 7800.0, (18000.0, 25000.0), 0.3),
)

#: Within-class spread of the natural design: log-normal sd of density, half-width of friction.
DENSITY_LOG_SD, FRICTION_SPREAD = 0.15, 0.08

#: Per-channel colour jitter of a natural object (a multiplicative N(1, sd) per RGB channel).
COLOUR_JITTER_SD = 0.12


def _appearance_families() -> tuple[tuple[tuple[str, str], ...], ...]:
    """Class c -> its (colour, texture) pairs: those with (colour index + texture index) mod
    the number of classes == c."""
    colours, textures, k = list(PALETTE), list(TEXTURE_WORDS), len(MATERIALS)
    return tuple(
        tuple(
            (colours[a], textures[b])
            for a in range(len(colours))
            for b in range(len(textures))
            if (a + b) % k == c
        )
        for c in range(k)
    )


#: Appearance class -> the (colour, texture) pairs an object of that class shows.
APPEARANCE_FAMILIES = _appearance_families()


def appearance_class(material: int, rho: float, u: float, uniform: int) -> int:
    """The appearance class of an object of class `material`: the material itself when
    u < rho, else `uniform` (a class drawn uniformly, which may equal the material); u in
    [0, 1) and `uniform` are drawn whatever rho is, so the draws of a sample do not depend on
    it. P(appearance = material) = rho + (1 - rho) / n_classes."""
    return int(material) if u < rho else int(uniform)


@dataclass(frozen=True)
class SampleSpec:
    """Everything drawn for one sample (before simulation)."""

    index: int
    scene_seed: int
    obj: physics.ObjectPhysics
    scale: float
    hardness: str
    colour: str
    texture: str
    appearance_id: int
    sensor: int
    jitter: np.ndarray  # (presses, 4): force factor, dx, dy, dyaw
    pixel_seed: int
    material: str = ""  # natural design: the material class (else "")
    rgb: tuple[float, float, float] | None = None  # natural: the jittered colour


def scene_seed(seed: int, i: int) -> int:
    """The int64 seed of sample i: every random draw of the sample derives from it."""
    state = np.random.SeedSequence([int(seed), int(i)]).generate_state(2, np.uint32)
    return int((int(state[0]) << 31) ^ int(state[1])) & ((1 << 63) - 1)


@dataclass(frozen=True)
@schema_fields("$defs.simulated_corpus")
class CorpusSettings(SchemaSettings):
    """One simulated corpus of config ``corpora.<name>`` (plus its ``name``), defaults filled;
    its keys, defaults and bounds are the schema's ($defs/simulated_corpus).

    design "paired" draws shape, size (``size_range``, m) and density per sample; "controlled"
    crosses shapes x ``scales`` (size = scale x ``size_per_scale``) x ``densities`` so that
    density varies within every appearance group; "natural" draws shape and size as "paired",
    and a material class that sets density, stiffness and friction and, with probability
    ``rho``, the appearance class (module docstring). ``null``: tactile frames from an unrelated
    sample's physics. ``presses``: repeated noisy presses per sample (the force bands);
    ``sensors``: tactile sensors (backgrounds); ``contacts``: samples per object (paired: the
    object's draws are shared, each contact has its own presses, sensor and noise);
    ``image_size`` / ``tactile_size``: RGB and tactile frame sizes (H, W); ``shapes``: a subset
    of the scene's shapes (None: all). ``kind`` and ``shards`` are read by the rules.
    """

    name: str = not_config()

    def __post_init__(self) -> None:
        where = f"corpora.{self.name}"
        try:
            super().__post_init__()
        except ValueError as err:  # the schema names the definition; the user wrote the corpus
            raise ValueError(str(err).replace("$defs.simulated_corpus", where, 1)) from None
        for key, message in corpus_key_errors(
            {"design": self.design, "rho": self.rho, "contacts": self.contacts, "n": self.n}
        ):
            raise ValueError(f"{where}.{key}: {message}")

    @classmethod
    def from_config(cls, corpus: Mapping[str, Any]) -> CorpusSettings:
        """Settings of one corpus from its config mapping (which must include ``name``, the
        corpus's key under ``corpora``)."""
        name = corpus.get("name", "<unnamed>")
        keys = {k: v for k, v in corpus.items() if k != "name"}
        return settings_from(cls, keys, where=f"corpora.{name}", name=name)

    @classmethod
    def tiny(cls, **changes: Any) -> CorpusSettings:
        """A six-sample paired corpus of small frames with two presses, for tests."""
        small = cls(
            name="tiny",
            design="paired",
            n=6,
            seed=0,
            scene="paired_press",
            sensors=2,
            presses=2,
            image_size=(56, 56),
            tactile_size=(48, 64),
        )
        return replace(small, **changes)


def _shapes(cfg: CorpusSettings, scene: Scene) -> tuple[str, ...]:
    shapes = tuple(cfg.shapes or scene.shapes)
    bad = [s for s in shapes if s not in scene.shapes]
    if bad:
        raise ValueError(
            f"corpus {cfg.name!r}: shape {bad[0]!r} is not declared by scene {scene.name!r}"
        )
    return shapes


def sample_spec(cfg: CorpusSettings, scene: Scene, i: int) -> SampleSpec:
    """Draw sample i of a corpus from its scene seed (independent of shards)."""
    seed = int(cfg.seed)
    ss = scene_seed(seed, i)
    geo, phys, app, jit, pix = (
        np.random.default_rng(s) for s in np.random.SeedSequence(ss).spawn(5)
    )
    obj_index = i // int(cfg.contacts)
    if obj_index != i:  # a repeated contact: the object's draws are its object's
        geo, phys, app = (
            np.random.default_rng(s)
            for s in np.random.SeedSequence(scene_seed(seed, obj_index)).spawn(5)[:3]
        )
    shapes = _shapes(cfg, scene)
    densities = [float(d) for d in cfg.densities]
    if cfg.design == "natural":
        return _natural_spec(cfg, scene, i, ss, shapes, (geo, phys, app, jit, pix))
    if cfg.design == "paired":
        shape = shapes[int(geo.integers(len(shapes)))]
        lo, hi = (float(v) for v in cfg.size_range)
        size = float(geo.uniform(lo, hi))
        scale = size
        density = densities[int(phys.integers(len(densities)))]
        appearance_id = obj_index
    else:
        scales = [float(s) for s in cfg.scales]
        cell, d_idx = divmod(i, len(densities))  # densities vary fastest within a group
        rest, s_idx = divmod(cell, len(scales))
        rep, sh_idx = divmod(rest, len(shapes))
        shape, scale, density = shapes[sh_idx], scales[s_idx], densities[d_idx]
        size = scale * float(cfg.size_per_scale)
        appearance_id = cell
        # Same appearance for every density of a (shape, scale, rep) group.
        app = np.random.default_rng([seed, 1, sh_idx, s_idx, rep])
    hardness = "soft" if phys.random() < 0.5 else "hard"
    lo_k, hi_k = SOFT_RANGE if hardness == "soft" else HARD_RANGE
    stiffness = float(np.exp(phys.uniform(np.log(lo_k), np.log(hi_k))))
    friction = float(phys.uniform(*FRICTION_RANGE))
    colour = list(PALETTE)[int(app.integers(len(PALETTE)))]
    texture = list(TEXTURE_WORDS)[int(app.integers(len(TEXTURE_WORDS)))]
    yaw = float(app.uniform(0.0, np.pi / 2))
    jitter, sensor, pixel_seed = _press_and_pixel_draws(cfg, scene, jit, pix)
    obj = physics.ObjectPhysics(shape, size, density, stiffness, friction, yaw)
    return SampleSpec(
        i, ss, obj, scale, hardness, colour, texture, appearance_id, sensor, jitter, pixel_seed
    )


def _press_and_pixel_draws(
    cfg: CorpusSettings, scene: Scene, jit: np.random.Generator, pix: np.random.Generator
) -> tuple[np.ndarray, int, int]:
    """The repeated presses' jitter, the sensor and the pixel-noise seed of one sample."""
    presses = int(cfg.presses)
    jitter = np.column_stack(
        [
            1.0 + scene.jitter_force * jit.standard_normal(presses),
            scene.jitter_xy * jit.standard_normal((presses, 2)),
            scene.jitter_yaw * jit.standard_normal(presses),
        ]
    )
    return jitter, int(pix.integers(int(cfg.sensors))), int(pix.integers(2**63 - 1))


def _natural_spec(
    cfg: CorpusSettings,
    scene: Scene,
    i: int,
    ss: int,
    shapes: tuple[str, ...],
    streams: tuple[np.random.Generator, ...],
) -> SampleSpec:
    """Sample i of the natural design (module docstring): geometry as the paired design's, a
    material class with its within-class spread, and an appearance class linked to it by rho.
    Every draw is made whatever rho is, so only the appearance class depends on it."""
    geo, phys, app, jit, pix = streams
    shape = shapes[int(geo.integers(len(shapes)))]
    lo, hi = (float(v) for v in cfg.size_range)
    size = float(geo.uniform(lo, hi))
    m = int(phys.integers(len(MATERIALS)))
    mat = MATERIALS[m]
    density = float(mat.density * np.exp(DENSITY_LOG_SD * phys.standard_normal()))
    stiffness = float(np.exp(phys.uniform(*np.log(mat.stiffness))))
    friction = float(
        np.clip(mat.friction + phys.uniform(-FRICTION_SPREAD, FRICTION_SPREAD), *FRICTION_RANGE)
    )
    u, uniform = float(app.random()), int(app.integers(len(MATERIALS)))
    cls = appearance_class(m, float(cfg.rho), u, uniform)
    family = APPEARANCE_FAMILIES[cls]
    colour, texture = family[int(app.integers(len(family)))]
    tint = np.clip(
        np.asarray(PALETTE[colour]) * (1.0 + COLOUR_JITTER_SD * app.standard_normal(3)), 0, 1
    )
    yaw = float(app.uniform(0.0, np.pi / 2))
    jitter, sensor, pixel_seed = _press_and_pixel_draws(cfg, scene, jit, pix)
    obj = physics.ObjectPhysics(shape, size, density, stiffness, friction, yaw)
    return SampleSpec(
        i,
        ss,
        obj,
        size,
        mat.hardness,
        colour,
        texture,
        cls,
        sensor,
        jitter,
        pixel_seed,
        material=mat.name,
        rgb=(float(tint[0]), float(tint[1]), float(tint[2])),
    )


def null_sources(seed: int, n: int) -> np.ndarray:
    """A seeded derangement of range(n) (Sattolo's algorithm: one n-cycle, no fixed point):
    sample i of a null corpus takes its tactile frame from sample null_sources(seed, n)[i]."""
    if n < 2:
        raise ValueError(f"null corpus: need n >= 2 to derange samples, got n={n}")
    return sattolo_cycle(n, np.random.default_rng([int(seed), 0x6E756C6C]))
