"""Helpers of the free knobs, whose settings are the generator's and the policy's own grids
(the steps and samplers of generate.samplers, the V-only cells of policy.sweep_*): their cells,
benchmark files and the run's own setting; included by rules/cost.smk."""

from tacgen_lib.policy.cells import all_cells as _policy_all_cells

TARGETS += ["results/report/cost_of_accuracy.html"]


# ------------------------------------------------------------------ generator knobs


def _steps_cells(sampler, steps):
    """generate_steps: the reference sampler at each of its steps."""
    return [
        (str(s), int(s), sampler, int(s))
        for s in sorted(int(x) for x in GENERATE["samplers"][sampler])
    ], str(steps)


def _sampler_cells(sampler, steps):
    """generate_sampler: each sampler at the reference steps (or its most)."""
    cells = []
    for i, (name, steps_list) in enumerate(GENERATE["samplers"].items()):
        st = steps if steps in [int(x) for x in steps_list] else max(steps_list)
        cells.append((f"{name} {int(st)}", i, name, int(st)))
    return cells, f"{sampler} {steps}"


_GENERATE_CELLS = {"generate_steps": _steps_cells, "generate_sampler": _sampler_cells}


def cost_generate(knob):
    """corpus, target, guidance, default label and cells (label, setting, sampler, steps);
    the default is the run's own reference cell (generate_ref)."""
    entry = COST_KNOB_CONFIG.get(knob) or {}
    corpus = entry.get("corpus") or GENERATE_CORPORA[0]
    target = entry.get("target") or next(iter(GENERATE["corpora"][corpus]))
    ref = generate_ref()
    cells, default = _GENERATE_CELLS[knob](ref["sampler"], ref["steps"])
    return corpus, target, ref["guidance"], default, cells


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


def _width_cells(s, v_cells):
    """policy_width: the V-only cells at the run's epochs."""
    widths = sorted({h for _, h, e, _ in v_cells if e == s.epochs})
    return [(str(h), h, h, s.epochs) for h in widths], str(s.hidden)


def _epochs_cells(s, v_cells):
    """policy_epochs: the V-only cells at the run's width."""
    epochs = sorted({e for _, h, e, _ in v_cells if h == s.hidden})
    return [(str(e), e, s.hidden, e) for e in epochs], str(s.epochs)


_POLICY_CELLS = {"policy_width": _width_cells, "policy_epochs": _epochs_cells}


def cost_policy(knob):
    """Default label, cells (label, setting, hidden, epochs) and the V-only cells of a policy
    knob; the default is the run's own width and epochs."""
    v_cells = [c for c in _policy_all_cells(POLICY_SETTINGS) if c[0] == "v"]
    cells, default = _POLICY_CELLS[knob](POLICY_SETTINGS, v_cells)
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


# ------------------------------------------------------------------ backbone families


def cost_backbone_bench():
    """(family, benchmark file) of every job that makes a family's backbones and the probe
    corpora's features: its own family_backbone jobs, or, for the main family, the main
    backbones and the main extraction of the probe corpora. The probes' cost, alike for every
    family, is left out."""
    out = []
    for family in FAMILIES.run:
        for m in MODALITIES:
            if family in OWN_FAMILIES:
                out.append(
                    (family, f"results/benchmarks/family_backbone/{family}/{m}.tsv")
                )
                continue
            out.append((family, f"results/benchmarks/pretrain_backbone/{m}.tsv"))
            what = "vision" if m == "vision" else f"tactile~{FAMILY_VARIANT}"
            out += [
                (family, f"results/benchmarks/extract_features/{c}/{what}.tsv")
                for c in FAMILY_CORPORA
            ]
    return out

# ------------------------------------------------------------------ the page
