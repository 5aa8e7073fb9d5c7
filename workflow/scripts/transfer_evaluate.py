"""Transfer to a second sensor: the transfer corpus's mass-quantile probes per heads view and
probe seed, the summary edge and the report page (rule transfer_evaluate)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

import numpy as np
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.objects import mass_quantile_classes, object_masses
from tacgen_lib.io import edges, log
from tacgen_lib.probes.transfer import (
    TransferSettings,
    TransferSplit,
    check_views,
    evaluate_transfer_seeds,
)
from tacgen_lib.report import transfer as report
from tacgen_lib.report.write import write_figure, write_table

logger = log.for_rule(snakemake)
corpus = snakemake.params.corpus
settings = TransferSettings.from_config(snakemake.params.settings)
manifest = edges.read(snakemake.input.manifest, columns=["corpus", "appearance_id", "mass"]).frame
rows = manifest[manifest["corpus"] == corpus].sort_values("sample_id", ignore_index=True)
ids = rows["sample_id"].to_numpy(dtype=object)
where = f"rule transfer_evaluate, corpus {corpus!r}"
masses = object_masses(rows, where=where)
classes = dict(
    zip(
        masses.index,
        mass_quantile_classes(masses.to_numpy(), settings.classes, where=where),
        strict=True,
    )
)
split = edges.read(snakemake.input.splits).frame.set_index("sample_id")["split"].reindex(ids)
if split.isna().any():
    raise edges.EdgeError(
        f"{snakemake.input.splits}: sample_id {split.index[split.isna()][0]!r} of corpus "
        f"{corpus} has no split; rebuild the splits"
    )
split = split.to_numpy(dtype=object)


def vectors(path, *columns):
    """The vector columns of an edge, rows in the order of `ids` (an absent id is an error
    naming the file and the id: `Edge.subset`)."""
    edge = edges.read(path, columns=columns, require=dict.fromkeys(columns, "vector"))
    rows = edge.subset(ids)
    return tuple(rows.vectors[c] for c in columns)


raw = (*vectors(snakemake.input.v, "vit"), *vectors(snakemake.input.t, "vit"))
check_views({"none": raw}, len(ids))
paths = iter(snakemake.input.aligned)  # the rule's order: heads seed, then view
aligned = {
    seed: {view: vectors(next(paths), "v_aligned", "t_aligned") for view in snakemake.params.views}
    for seed in snakemake.params.heads_seeds
}
objects = rows["appearance_id"].to_numpy()
y = np.array([classes[o] for o in objects])
data = TransferSplit(y=y, objects=objects, split=split)
logger.info(
    "%s: %d contacts of %d objects (%d test objects), %d mass classes, views %s, heads seeds %s",
    corpus,
    len(ids),
    len(masses),
    len(set(objects[split == "test"])),
    settings.classes,
    ["none", *snakemake.params.views],
    list(snakemake.params.heads_seeds),
)
with threadpool_limits(snakemake.threads):
    summary = evaluate_transfer_seeds(
        raw, aligned, data, settings, heads_from=snakemake.params.views, progress=logger.info
    )
edges.write(snakemake.output.summary, summary, key="row_id", producer=snakemake.rule)
notes = report.transfer_sentences(summary, corpus)
write_table(
    report.transfer_table(summary),
    snakemake.output.table,
    title=f"Transfer to a second sensor: mass tertiles of unseen objects ({corpus})",
    mono=(),
    notes=notes,
)
write_figure(report.transfer_figure(summary, corpus), snakemake.output.figure)
for note in notes:
    logger.info("%s", note)
