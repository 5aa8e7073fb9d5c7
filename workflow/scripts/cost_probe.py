"""One replicate of a probe knob's setting: the headline V vs V+T probe of one family with B
bootstrap resamples or B tactile permutations drawn from replicate seed {rep} (rule cost_probe).

The probes are fitted exactly as rule probe fits them (`protocol.fit_probe` at the first probe
seed, concat fusion, the heads' preprocessing variant); only the bootstrap or permutation seed
changes between replicates, so their spread is the Monte Carlo error of B draws.
"""

import pandas as pd
from threadpoolctl import threadpool_limits

from tacgen_lib.corpus.splits import assert_trainable
from tacgen_lib.io import edges, log
from tacgen_lib.probes.bootstrap import fixed_test_bootstrap
from tacgen_lib.probes.controls import PairedRows, tactile_permutation_control
from tacgen_lib.probes.fusion import fuse
from tacgen_lib.probes.protocol import ProbeSettings, family_rows, fit_probe, strata_for

logger = log.for_rule(snakemake)
w, params = snakemake.wildcards, snakemake.params
family, corpus = params.family, params.corpus
b, rep = int(w.value), int(w.rep)
settings = ProbeSettings.from_config(params.settings, family["kind"], int(params.probe_seed))
manifest = edges.read(snakemake.input.manifest).frame
splits = edges.read(snakemake.input.splits).frame
rows = family_rows(
    manifest, splits, corpus=family["corpus"], target=family["target"], kind=family["kind"],
    strata=strata_for(corpus),
)  # fmt: skip
assert_trainable(rows.train_ids, splits, rule=snakemake.rule, allowed=("train", "val"))
v_tr, v_te = rows.train_test(
    edges.read(snakemake.input.vision, require={family["vision"]: "vector"}), family["vision"]
)
t_tr, t_te = rows.train_test(edges.read(snakemake.input.tactile, require={"vit": "vector"}), "vit")
logger.info("%s = %d, replicate seed %d: %s probe of %s on %s (%d train/val, %d test rows)",
            w.knob, b, rep, family["kind"], family["target"], family["corpus"], rows.n_train,
            rows.n_test)  # fmt: skip
ids = {"train_ids": rows.train_ids, "test_ids": rows.test_ids}
with threadpool_limits(snakemake.threads):
    p_v = fit_probe(v_tr, rows.y_train, v_te, settings, **ids)
    p_vt = fit_probe(fuse("concat", v_tr, t_tr), rows.y_train, fuse("concat", v_te, t_te),
                     settings, **ids)  # fmt: skip
    row = {"row_id": f"{w.knob}|{b}|rep~{rep}", "label": w.value, "rep": rep}
    if w.knob == "probe_bootstrap":
        out = fixed_test_bootstrap(
            rows.y_test, p_v.pred_test, p_vt.pred_test, settings.metric, n_resamples=b,
            seed=rep, strata=rows.strata_test, sample_ids=rows.test_ids,
        )  # fmt: skip
        row |= {"delta": out["delta"], "ci_low": out["ci_low"], "ci_high": out["ci_high"]}
    elif w.knob == "probe_permutations":
        paired = PairedRows(v_tr, t_tr, rows.y_train, v_te, t_te, rows.y_test, "concat")
        out = tactile_permutation_control(
            paired, probe=p_vt.fixed(settings.kind), probe_v=p_v.fixed(settings.kind),
            metric=settings.metric, n_permutations=b, seed=rep,
        )  # fmt: skip
        row |= {"n_permutations": b, "delta_ctrl": out["delta_ctrl"],
                "delta_ctrl_sd": out["delta_sd"]}  # fmt: skip
    else:
        raise ValueError(f"rule {snakemake.rule}: {w.knob!r} is not a probe knob")
edges.write(snakemake.output.rows, pd.DataFrame([row]), key="row_id", producer=snakemake.rule)
logger.info("%s", {k: v for k, v in row.items() if k != "row_id"})
