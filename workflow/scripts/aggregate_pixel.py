"""The pixel generators' summary (utility ⋈ reconstruction ⋈ wall times) and the page Pixel
generators (rule aggregate_pixel)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import io
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from tacgen_lib.generate.pixel.frames import paired_frames
from tacgen_lib.generate.pixel.utility import arm_generator
from tacgen_lib.io import edges, hashed, log
from tacgen_lib.preprocess.frames import decode_frames
from tacgen_lib.report import pixel as report
from tacgen_lib.report.write import write_figure, write_table
from tacgen_lib.runtime.benchmarks import benchmark_seconds

logger = log.for_rule(snakemake)
inp, out, params = snakemake.input, snakemake.output, snakemake.params


def frame_of(paths):
    return pd.concat([edges.read(p).frame for p in paths], ignore_index=True)


rows = frame_of(inp.rows)
reconstruction = frame_of(inp.reconstruction)
points = frame_of(inp.points)
latent = edges.read(inp.latent).frame
ref = params.latent_ref
latent = latent[
    (latent["sampler"] == ref["sampler"])
    & (latent["guidance"] == float(ref["guidance"]))
    & (latent["steps"] == int(ref["steps"]))
]
view = report.utility_view(rows, latent)

# wall times (benchmark files, never in a hashed edge): training + sampling per arm
train_s = {
    (Path(p).parts[-3], Path(p).parts[-2], int(Path(p).stem)): benchmark_seconds(p)
    for p in inp.train_bench
}
sample_s = {
    (Path(p).parts[-3], Path(p).parts[-2], int(Path(p).stem)): benchmark_seconds(p)
    for p in inp.sample_bench
}


def seconds(corpus, arm, seed):
    base = arm.removesuffix("_cal")
    if base.startswith("t_") or base in ("latent", "real_lowres"):
        return np.nan
    generator = arm_generator(base)[0]
    return train_s.get((corpus, generator, int(seed)), np.nan) + sample_s.get(
        (corpus, base, int(seed)), np.nan
    )


view["seconds"] = [
    seconds(c, a, s) for c, a, s in zip(view["corpus"], view["arm"], view["seed"], strict=True)
]
summary = view.merge(
    reconstruction.drop(columns=["row_id", "generator", "guidance", "steps", "calibrated"]),
    on=["corpus", "seed", "arm"],
    how="left",
)
sink = io.BytesIO()
pq.write_table(pa.Table.from_pandas(summary, preserve_index=False), sink, compression="zstd")
hashed.atomic_write_bytes(out.summary, sink.getvalue())

notes = report.architecture_sentences(view, reconstruction)
curve_notes = report.curve_sentences(points)
write_table(
    report.architecture_table(view, reconstruction),
    out.architecture,
    title="Pixel generators: reconstruction and utility on the same test rows",
    mono=(),
    lead=notes + [f"Scale curve (figure curve): {c}" for c in curve_notes],
    notes=[
        "Perceptual distance: LPIPS needs ImageNet-trained weights that cannot be downloaded "
        "here; the frozen tactile ViT's matched-pair cosine (centred on the real train mean, "
        "beside the off-diagonal mean) stands in for it."
    ],
)
write_table(
    report.calibration_table(reconstruction, view),
    out.calibration,
    title="Contrast calibration (gain fitted on train rows) and its effect on utility",
    mono=(),
)
write_figure(report.curve_figure(points), out.curve)
write_figure(report.scatter_figure(view, reconstruction), out.scatter)

# filmstrips: the first test rows of the first judged corpus and seed
splits = edges.read(inp.splits).frame
test = sorted(
    splits.loc[(splits["corpus"] == params.corpus) & (splits["split"] == "test"), "sample_id"]
)
show = test[:5]
rgb, real = paired_frames(
    edges.read(inp.samples, columns=["rgb"]).subset(show).frame,
    edges.read(inp.tactile, columns=["tactile_proc"]).subset(show).frame,
    tuple(params.size),
    rgb_where=inp.samples,
    tactile_where=inp.tactile,
)
done = set()
for arm, path in zip(params.arms, inp.frames, strict=True):
    name = f"filmstrip_{arm_generator(arm)[0]}"
    if name in done:
        continue  # one filmstrip per generator: its first arm
    done.add(name)
    gen = decode_frames(edges.read(path).subset(show).frame, "frame", where=path)
    write_figure(
        report.filmstrip_figure(
            rgb, real, gen, sample_ids=show, title=f"{report.arm_label(arm)} ({params.corpus})"
        ),
        out[name],
    )
for note in notes + curve_notes:
    logger.info("%s", note)
