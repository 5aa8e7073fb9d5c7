"""The trained generator without torch: its weights file and the denoiser's forward pass in numpy.

This module owns what sampling needs, so that a `sample_generator` job imports numpy and
pyarrow only. Importing torch costs ~1.2 s per process here, more than sampling a corpus at
the default size, and the default grid runs 36 sampling jobs (benchmarks/bench_generate.py
prints both):

- the weights file (`encode_generator` / `read_generator`): one Arrow IPC table with a row per
  array (name, dtype, shape, raw little-endian bytes) and the settings, seed and training curve
  as JSON in the schema metadata. The bytes depend only on the arrays and the metadata (no
  timestamps, unlike a zip), so the same fit writes the same file.
- `DenoiserArrays`: the forward pass of `model.Denoiser` in float32 numpy on its state dict,
  equal to the torch module up to float rounding (tests/generate/test_generate.py). Training stays in
  torch (`train`); only inference is here.
- `sinusoidal_embedding`, `Standardiser` and `fit_standardiser`, shared with the torch model.
"""

from __future__ import annotations

import io
import json
import math
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np
import pyarrow as pa

from tacgen_lib.generate.schedules import Schedule, make_schedule
from tacgen_lib.generate.settings import GenerateSettings
from tacgen_lib.io import hashed

__all__ = [
    "FORMAT",
    "DenoiserArrays",
    "GeneratorRecord",
    "GeneratorWeights",
    "Standardiser",
    "encode_generator",
    "fit_standardiser",
    "read_generator",
    "sinusoidal_embedding",
]

#: The weights file's format tag (schema metadata); a file without it is refused.
FORMAT = "tacgen-generator-v2"
_META_KEY = b"tacgen.generator"
#: torch.nn.LayerNorm's default epsilon, which the trained model used.
LAYER_NORM_EPS = 1e-5


def sinusoidal_embedding(t: np.ndarray, dim: int, max_period: float = 10_000.0) -> np.ndarray:
    """Transformer-style sinusoidal embedding of (integer) timesteps: (B,) -> (B, dim) float32.

    Frequencies max_period^(-k / half), k = 0 .. half-1, formed in float64 and rounded to
    float32 (so t up to 1000 stays exact enough); cos then sin, an odd `dim` gets a zero column.
    """
    if dim < 2:
        raise ValueError(f"time embedding dim must be >= 2, got {dim}")
    half = dim // 2
    freqs = np.exp(-math.log(max_period) * np.arange(half, dtype=np.float64) / half)
    args = np.asarray(t, dtype=np.float32)[:, None] * freqs.astype(np.float32)[None, :]
    emb = np.concatenate([np.cos(args), np.sin(args)], axis=1)
    if dim % 2:
        emb = np.concatenate([emb, np.zeros_like(emb[:, :1])], axis=1)
    return emb.astype(np.float32, copy=False)


@dataclass(frozen=True)
class Standardiser:
    """Per-dimension standardisation with train-split statistics (stored beside the weights).

    A dimension whose train values are constant (sd = 0, or below `min_sd` relative to the
    largest sd) has scale 1: it is centred, never divided by zero, and comes back exactly.
    """

    mean: np.ndarray  # (d,) float64
    scale: np.ndarray  # (d,) float64, > 0

    def forward(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=np.float64) - self.mean) / self.scale

    def inverse(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(z, dtype=np.float64) * self.scale + self.mean


def fit_standardiser(x: np.ndarray, min_sd: float = 1e-6) -> Standardiser:
    """Mean and sd of the training rows (float64); zero-variance dimensions get scale 1."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 1:
        raise ValueError(f"standardiser: expected (n >= 1, d) training features, got {x.shape}")
    mean = x.mean(axis=0)
    sd = x.std(axis=0)
    floor = min_sd * max(float(sd.max(initial=0.0)), 1.0)
    scale = np.where(sd > floor, sd, 1.0)
    return Standardiser(mean=mean, scale=scale)


def _silu(x: np.ndarray) -> np.ndarray:
    """x sigmoid(x) = x / (1 + exp(-x)) into one new array (float32); the argument of exp is
    clipped at 80 so it never overflows (silu(x) < 1e-33 in magnitude below x = -80)."""
    out = np.maximum(x, np.float32(-80.0))
    np.negative(out, out=out)
    np.exp(out, out=out)
    out += np.float32(1.0)
    return np.divide(x, out, out=out)


def _layer_norm(x: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """torch.nn.LayerNorm over the last axis: biased variance, eps inside the square root."""
    centred = x - x.mean(axis=1, keepdims=True)
    var = np.einsum("ij,ij->i", centred, centred)[:, None] / np.float32(x.shape[1])
    centred *= weight / np.sqrt(var + np.float32(LAYER_NORM_EPS))
    centred += bias
    return centred


@dataclass(frozen=True)
class DenoiserArrays:
    """`model.Denoiser`'s forward pass on its state dict (float32 numpy arrays, same names).

    Same structure: x_t -> inp -> `blocks` residual blocks x + fc2(silu(fc1(silu(norm(x) + e))))
    with e = emb(time(sin(t)) + cond(c)) -> out(silu(out_norm(h))); rows where ``drop`` is True
    take the learned null condition.
    """

    dims: Mapping[str, int]
    params: Mapping[str, np.ndarray]

    @classmethod
    def from_state(cls, state: Mapping[str, Any], dims: Mapping[str, int]) -> DenoiserArrays:
        """From a torch state dict (tensors or arrays); every array is copied to float32."""
        params = {
            k: np.ascontiguousarray(np.asarray(v, dtype=np.float32)) for k, v in state.items()
        }
        missing = [k for k in _state_names(dims["blocks"]) if k not in params]
        if missing:
            raise ValueError(f"denoiser state lacks {missing}")
        return cls(dict(dims), params)

    def _linear(self, name: str, x: np.ndarray, bias: bool = True) -> np.ndarray:
        y = x @ self.params[f"{name}.weight"].T
        if bias:
            y += self.params[f"{name}.bias"]
        return y

    def _mlp(self, name: str, x: np.ndarray) -> np.ndarray:
        return self._linear(f"{name}.2", _silu(self._linear(f"{name}.0", x)))

    def condition(self, cond: np.ndarray, drop: np.ndarray | None = None) -> np.ndarray:
        """cond (B, d_v) with the rows where ``drop`` is True replaced by the null condition."""
        cond = np.asarray(cond, dtype=np.float32)
        if drop is None:
            return cond
        return np.where(np.asarray(drop, bool)[:, None], self.params["null_condition"], cond)

    def _time(self, t: np.ndarray) -> np.ndarray:
        return self._mlp("time", sinusoidal_embedding(t, self.dims["time_dim"]))

    def _head(self, h: np.ndarray) -> np.ndarray:
        p = self.params
        return self._linear("out", _silu(_layer_norm(h, p["out_norm.weight"], p["out_norm.bias"])))

    def _blocks(self, x_t: np.ndarray, embeddings: list[np.ndarray]) -> np.ndarray:
        h = self._linear("inp", np.asarray(x_t, dtype=np.float32))
        for k, e in enumerate(embeddings):
            b = f"blocks.{k}"
            z = _layer_norm(h, self.params[f"{b}.norm.weight"], self.params[f"{b}.norm.bias"]) + e
            h = h + self._linear(f"{b}.fc2", _silu(self._linear(f"{b}.fc1", _silu(z))))
        return self._head(h)

    def forward(
        self, x_t: np.ndarray, t: np.ndarray, cond: np.ndarray, drop: np.ndarray | None = None
    ) -> np.ndarray:
        """x_t (B, d_t), t (B,) integer steps, cond (B, d_v); drop (B,) bool -> null condition."""
        emb = self._time(np.asarray(t)) + self._mlp("cond", self.condition(cond, drop))
        n = self.dims["blocks"]
        return self._blocks(x_t, [self._linear(f"blocks.{k}.emb", emb) for k in range(n)])

    def project_condition(
        self, cond: np.ndarray, drop: np.ndarray | None = None
    ) -> list[np.ndarray]:
        """What fixed condition rows contribute to each block's embedding: W_k cond_emb per
        block k, (B, hidden) each, without the bias. Sampling computes it once per batch
        (`forward_projected` adds the time part per step) instead of once per step."""
        c = self._mlp("cond", self.condition(cond, drop))
        n = self.dims["blocks"]
        return [self._linear(f"blocks.{k}.emb", c, bias=False) for k in range(n)]

    def forward_projected(self, x_t: np.ndarray, t: int, projected: list[np.ndarray]) -> np.ndarray:
        """`forward` for rows that share one timestep t, the condition part precomputed by
        `project_condition`: equal to it up to float rounding, since each block's embedding
        layer is linear, W (time + cond) + b = (W time + b) + W cond. The time MLP then runs on
        one row per step and the condition MLP never (sampling: about half the FLOPs)."""
        time = self._time(np.array([int(t)]))  # (1, hidden)
        return self._blocks(
            x_t, [pc + self._linear(f"blocks.{k}.emb", time) for k, pc in enumerate(projected)]
        )


def _state_names(blocks: int) -> list[str]:
    names = [
        "inp.weight",
        "inp.bias",
        "null_condition",
        "out_norm.weight",
        "out_norm.bias",
        "out.weight",
        "out.bias",
    ]
    for mlp in ("time", "cond"):
        names += [f"{mlp}.{i}.{p}" for i in (0, 2) for p in ("weight", "bias")]
    for k in range(blocks):
        names += [
            f"blocks.{k}.{layer}.{p}"
            for layer in ("norm", "emb", "fc1", "fc2")
            for p in ("weight", "bias")
        ]
    return names


@dataclass(frozen=True)
class GeneratorRecord:
    """What a trained generator carries besides its network: the train-split standardiser, the
    settings, the seed and the training curve (best step, early stopping)."""

    standardiser: Standardiser
    settings: GenerateSettings
    seed: int
    curve: list[dict] = field(default_factory=list)
    best_step: int = 0
    best_val_loss: float = float("nan")
    steps_run: int = 0
    stopped_early: bool = False

    @property
    def schedule(self) -> Schedule:
        return make_schedule(self.settings.schedule, self.settings.train_steps)

    def record(self) -> dict[str, Any]:
        """The record's fields by name (to build another view of the same generator)."""
        return {f.name: getattr(self, f.name) for f in fields(GeneratorRecord)}


@dataclass(frozen=True)
class GeneratorWeights(GeneratorRecord):
    """A trained generator as sampling reads it: its record and the EMA denoiser's arrays."""

    denoiser: DenoiserArrays = field(kw_only=True)


def encode_generator(weights: GeneratorWeights) -> bytes:
    """The weights file's bytes: a row per array (denoiser state in float32, then the
    standardiser's mean and scale in float64) and everything else as JSON metadata."""
    arrays = dict(weights.denoiser.params)
    arrays["standardiser.mean"] = np.asarray(weights.standardiser.mean, np.float64)
    arrays["standardiser.scale"] = np.asarray(weights.standardiser.scale, np.float64)
    names = sorted(arrays)
    meta = {
        "format": FORMAT,
        "dims": dict(weights.denoiser.dims),
        "settings": {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(weights.settings).items()
        },
        "seed": int(weights.seed),
        "curve": [dict(c) for c in weights.curve],
        "best_step": int(weights.best_step),
        "best_val_loss": float(weights.best_val_loss),
        "steps_run": int(weights.steps_run),
        "stopped_early": bool(weights.stopped_early),
    }
    table = pa.table(
        {
            "name": pa.array(names, pa.string()),
            "dtype": pa.array([arrays[n].dtype.str for n in names], pa.string()),
            "shape": pa.array([list(arrays[n].shape) for n in names], pa.list_(pa.int64())),
            "data": pa.array(
                [np.ascontiguousarray(arrays[n]).tobytes() for n in names], pa.binary()
            ),
        }
    ).replace_schema_metadata({_META_KEY: json.dumps(meta, sort_keys=True).encode()})
    sink = io.BytesIO()
    with pa.ipc.new_file(sink, table.schema) as writer:
        writer.write_table(table)
    return sink.getvalue()


def read_generator(path: str | os.PathLike[str], *, verify: bool = True) -> GeneratorWeights:
    """A weights file written by `encode_generator` (through `train.save_generator`), its
    sidecar hash checked first. Raises ValueError naming the file if it is not one."""
    if verify:
        hashed.verify(path)
    try:
        with pa.memory_map(os.fspath(path)) as source:
            table = pa.ipc.open_file(source).read_all()
        meta = json.loads((table.schema.metadata or {})[_META_KEY])
    except Exception as exc:  # noqa: BLE001 - re-raised with the file named
        raise ValueError(
            f"{path}: not a readable generator ({exc}); rerun train_generator"
        ) from exc
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: not a {FORMAT} file; rerun train_generator")
    cols = table.to_pydict()
    arrays = {
        n: np.frombuffer(d, dtype=np.dtype(dt)).reshape(s).copy()
        for n, dt, s, d in zip(
            cols["name"], cols["dtype"], cols["shape"], cols["data"], strict=True
        )
    }
    std = Standardiser(arrays.pop("standardiser.mean"), arrays.pop("standardiser.scale"))
    # JSON gives lists back: a settings grid is a tuple
    s = {k: tuple(v) if isinstance(v, list) else v for k, v in meta["settings"].items()}
    return GeneratorWeights(
        std,
        GenerateSettings(**s),
        int(meta["seed"]),
        list(meta["curve"]),
        int(meta["best_step"]),
        float(meta["best_val_loss"]),
        int(meta["steps_run"]),
        bool(meta["stopped_early"]),
        denoiser=DenoiserArrays.from_state(arrays, meta["dims"]),
    )
