"""Every arm of the regime for one corpus x seed: linear and nonlinear V, the generator ladder
(look oracle, kNN, ridge, kernel ridge, the diffusion generator's mean and one sample), the
shuffled pool, generalised distillation, V + real T, the V ceiling and the vision ceiling, per
labelled draw, labelled size and pool size (rule regime_evaluate). With params
look_control_snr (rule regime_look_control): the positive control, the arms that need no
generator on the look's mean touch plus noise (tacgen_lib.generate.look_control)."""

from tacgen_lib.runtime.preload import run_in_preloaded_interpreter

run_in_preloaded_interpreter(snakemake)  # returns only if no preloaded interpreter takes the job

from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.looks import look_levels, visible_factors
from tacgen_lib.generate.ladder import ladder_rungs
from tacgen_lib.generate.look_control import look_control_touch
from tacgen_lib.generate.regime import (
    RegimeSettings,
    RegimeTarget,
    evaluate_regime,
    job_regime_sets,
    regime_probe_settings,
    regime_test_rows,
)
from tacgen_lib.generate.regime_sets import PAIRINGS
from tacgen_lib.generate.visibility import VisibilitySettings
from tacgen_lib.io import edges, log
from tacgen_lib.probes.rows import family_rows
from tacgen_lib.probes.settings import ProbeSettings

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
regime = RegimeSettings.from_config(params.regime)
seed = int(w.seed)
splits = edges.read(snakemake.input.splits, require={"split": "str", "corpus": "str"}).frame
manifest = edges.read(snakemake.input.manifest).frame
# the probes fit on labelled rows, the ladder and the distillation teacher on pool rows:
# never a test row
sets = job_regime_sets(splits, w.corpus, regime, seed, rule=snakemake.rule)
ceiling_rows = manifest.set_index("sample_id")[["appearance_id", "shape", "scale"]]
corpus_rows = manifest.loc[manifest["corpus"] == w.corpus]
# the appearance classes of the natural design (0 .. k-1)
n_classes = int(corpus_rows["appearance_id"].max()) + 1
targets = []
for target, kind in params.targets.items():
    rows = family_rows(manifest, splits, corpus=w.corpus, target=target, kind=kind)
    settings = ProbeSettings.from_config(params.probes, kind, params.probe_seed)
    targets.append(
        RegimeTarget(
            regime_test_rows(rows, sets),
            regime_probe_settings(settings, regime),
            ceiling_rows.loc[list(rows.train_ids) + list(rows.test_ids)],
        )
    )

vision = edges.read_vector_map(snakemake.input.v, "vit")
t_real = edges.read_vector_map(snakemake.input.t, "vit")
looks = look_levels(visible_factors(corpus_rows))
control = params.look_control_snr is not None
if control:
    # the look's mean real touch (over the non-test rows) plus noise replaces real touch
    reference = splits.loc[
        (splits["corpus"] == w.corpus) & (splits["split"] != "test"), "sample_id"
    ].astype(str)
    built = look_control_touch(
        t_real, looks[-1], reference, list(t_real), snr=params.look_control_snr, seed=seed
    )
    t_real = built.t_control
    logger.info("%s seed %d positive control: %s", w.corpus, seed, built.describe())
# (pool size, pairing) -> its generator's edge; none in the positive control
generators = (
    {} if control else dict(zip(map(tuple, params.cells), snakemake.input.t_gen, strict=True))
)
t_gen, ladder = {}, {}
needed = sorted(str(i) for i in [*sets.labelled_union(regime.label_draws), *sets.test])
with threadpool_limits(1):
    for n_pool in sorted({int(n) for n, _ in params.cells}):
        for pairing in PAIRINGS:
            if (n_pool, pairing) in generators:
                path = generators[(n_pool, pairing)]
                t_gen[(n_pool, pairing)] = edges.read_vector_map(path, "t_gen")
        real = generators.get((n_pool, "real"))
        rungs = ladder_rungs(
            vision,
            t_real,
            looks,
            sets.pool_ids(n_pool),
            needed,
            None if real is None else edges.read_vector_map(real, "t_gen_mean"),
            regime=regime,
            seed=seed,
        )
        ladder[n_pool] = rungs.t_gen
        logger.info("%s seed %d N_P=%d: %s", w.corpus, seed, n_pool, rungs.describe())
    # one BLAS thread in this process or in each of the job's workers (fork_map): the rows do
    # not depend on the cores Snakemake gives the job
    rows = evaluate_regime(
        targets,
        sets,
        regime,
        None if control else VisibilitySettings.from_config(params.ceiling),
        corpus=w.corpus,
        rho=float(params.rho),
        seed=seed,
        vision=vision,
        t_real=t_real,
        t_gen=t_gen,
        ladder=ladder,
        gammas=params.gammas,
        n_classes=n_classes,
        progress=logger.info,
        workers=snakemake.threads,
        distil=not control,
    )
edges.write(snakemake.output.rows, rows, key="row_id", producer=snakemake.rule)
logger.info("%d regime rows", len(rows))
