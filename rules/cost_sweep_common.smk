"""Helpers of the align, probes, generator and policy knob sweeps (knob names, their settings
and input lists, the default's setting of each); included by rules/cost.smk."""

from tacgen_lib.generate.cells import guidance_text as _guidance_text
from tacgen_lib.policy.cells import all_cells as _policy_all_cells

ALIGN_KNOBS = ["align_steps", "align_n"]
PROBE_KNOBS = ["probe_bootstrap", "probe_permutations"]
GENERATE_KNOBS = ["generate_steps", "generate_sampler"]
POLICY_KNOBS = ["policy_width", "policy_epochs"]
register_cost_knobs("align", ALIGN_KNOBS)
register_cost_knobs("probes", PROBE_KNOBS)
register_cost_knobs("generate", GENERATE_KNOBS, free=bool(GENERATE_CORPORA))
register_cost_knobs("policy", POLICY_KNOBS, free=POLICY_ON)
for _k in GENERATE_KNOBS + POLICY_KNOBS:
    if "values" in cost_knob(_k):
        raise ValueError(
            f"config cost.knobs.{_k}: its settings are the stage's own grid "
            "(generate.samplers, policy.sweep_hidden / sweep_epochs); widen that instead"
        )
TARGETS += ["results/report/cost_of_accuracy.html"]


def _text(values):
    return [str(v) for v in values]


# ------------------------------------------------------------------ alignment knobs


def cost_align(knob):
    """(corpus, variant, seeds, value labels) of an alignment knob."""
    entry = cost_knob(knob)
    heads = config["probes"]["heads"]
    return (
        entry.get("corpus") or ALIGN_CORPORA[0],
        heads["variant"],
        entry.get("seeds") or ALIGN["seeds"],
        _text(entry.get("values") or []),
    )


def cost_align_cells(knob):
    _, _, seeds, values = cost_align(knob)
    return [(v, str(s)) for v in values for s in seeds]


def cost_align_files(pattern):
    def files(wildcards):
        return [
            pattern.format(knob=wildcards.knob, value=v, seed=s)
            for v, s in cost_align_cells(wildcards.knob)
        ]

    return files


# ------------------------------------------------------------------ probe knobs


def cost_probe_family(knob):
    return probe_family(cost_knob(knob).get("family", "force"))


def cost_probe_cells(knob):
    entry = cost_knob(knob)
    return [
        (v, str(r))
        for v in _text(entry.get("values") or [])
        for r in range(int(entry.get("replicates", 5)))
    ]


def cost_probe_files(pattern):
    def files(wildcards):
        return [
            pattern.format(knob=wildcards.knob, value=v, rep=r)
            for v, r in cost_probe_cells(wildcards.knob)
        ]

    return files


def cost_probe_inputs(wildcards):
    fam = cost_probe_family(wildcards.knob)
    return {
        "manifest": "results/corpus/manifest.parquet",
        "splits": "results/corpus/splits.parquet",
        "vision": feature_edge(fam["corpus"], "vision"),
        "tactile": feature_edge(fam["corpus"], "tactile", PROBES["heads"]["variant"]),
    }


# ------------------------------------------------------------------ generator knobs


def _generate_ref(gen):
    """(sampler, steps, guidance text) of a generate config's reference cell."""
    sampler = next(iter(gen["samplers"]))
    ws = [_guidance_text(w) for w in gen["guidance"]]
    return (
        sampler,
        max(int(s) for s in gen["samplers"][sampler]),
        ("1" if "1" in ws else ws[0]),
    )


def cost_generate(knob):
    """corpus, target, guidance, default label and cells (label, setting, sampler, steps)."""
    entry = cost_knob(knob)
    corpus = entry.get("corpus") or GENERATE_CORPORA[0]
    target = entry.get("target") or next(iter(GENERATE["corpora"][corpus]))
    sampler, steps, guidance = _generate_ref(GENERATE)
    d_sampler, d_steps, _ = _generate_ref(DEFAULT_CONFIG["generate"])
    if knob == "generate_steps":
        cells = [
            (str(s), int(s), sampler, int(s))
            for s in sorted(int(x) for x in GENERATE["samplers"][sampler])
        ]
        default = str(d_steps) if sampler == d_sampler else None
    else:
        cells = []
        for i, (name, steps_list) in enumerate(GENERATE["samplers"].items()):
            st = d_steps if d_steps in [int(x) for x in steps_list] else max(steps_list)
            cells.append((f"{name} {int(st)}", i, name, int(st)))
        default = f"{d_sampler} {d_steps}"
    return corpus, target, guidance, default, cells


def cost_generate_bench(knob):
    corpus, _, guidance, _, cells = cost_generate(knob)
    out = [
        (
            (label, str(seed)),
            sample_benchmark(corpus, seed, sampler, guidance, steps),
        )
        for label, _, sampler, steps in cells
        for seed in GENERATE["seeds"]
    ]
    return out


# ------------------------------------------------------------------ policy knobs


def cost_policy(knob):
    """Default label and cells (label, setting, hidden, epochs) of a policy knob: the V-only
    cells at the default epochs (width) or the default width (epochs)."""
    s = POLICY_SETTINGS
    v_cells = [c for c in _policy_all_cells(s) if c[0] == "v"]
    if knob == "policy_width":
        values = sorted({h for _, h, e, _ in v_cells if e == s.epochs})
        cells = [(str(h), h, h, s.epochs) for h in values]
        default = str(DEFAULT_CONFIG["policy"]["hidden"])
    else:
        values = sorted({e for _, h, e, _ in v_cells if h == s.hidden})
        cells = [(str(e), e, s.hidden, e) for e in values]
        default = str(DEFAULT_CONFIG["policy"]["epochs"])
    return default, cells, v_cells


def cost_policy_bench(knob):
    _, cells, v_cells = cost_policy(knob)
    out = []
    for label, _, h, e in cells:
        for c in v_cells:
            if (c[1], c[2]) != (h, e):
                continue
            name = policy_cell_name(c)
            out.append(
                ((label, str(c[3])), f"results/benchmarks/train_policy/{name}.tsv")
            )
            out += [
                (
                    (label, str(c[3])),
                    f"results/benchmarks/rollout_policy/{name}/{k}.tsv",
                )
                for k in range(POLICY_SETTINGS.rollout_shards)
            ]
    return out

# ------------------------------------------------------------------ the page
