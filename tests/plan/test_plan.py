"""The workflow's plan (tacgen_lib.plan): what the rules expand and ask for, read from the
validated config; the rule files only name it (tests/test_architecture.py)."""

from __future__ import annotations

import copy
import os
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from tacgen_lib.plan.align import AlignPlan
from tacgen_lib.plan.cost import CostPlan, write_source
from tacgen_lib.plan.paths import MATCHES_NOTHING, benchmark_file, none_of, one_of
from tacgen_lib.plan.pixel import PixelPlan
from tacgen_lib.plan.report_items import findings_inputs
from tacgen_lib.plan.stages import StagePlans
from tacgen_lib.plan.transfer import TransferPlan
from tacgen_lib.workflow_config import ConfigError, validate_config
from tests.snakemake_run import ROOT, merged_config, validated
from tests.test_config_defaults import rule_file_python


@pytest.fixture(scope="module")
def default() -> dict:
    return validated()


@pytest.fixture(scope="module")
def tiny() -> dict:
    return validated("test.yaml")


def test_one_of_matches_exactly_its_names_and_none_of_everything_else():
    pattern = re.compile(f"^(?:{one_of(['sim_a', 'sim.b'])})$")
    assert pattern.match("sim_a") and pattern.match("sim.b")
    assert not pattern.match("simxb") and not pattern.match("sim_ab")
    assert one_of([]) == MATCHES_NOTHING and not re.match(MATCHES_NOTHING, "anything")
    other = re.compile(f"^{none_of(['sim_a'])}$")
    assert other.match("sim_ab") and other.match("sim_b") and not other.match("sim_a")
    assert not other.match("a/b"), "a wildcard segment never spans a folder"


def test_benchmark_file_is_the_benchmark_directive_path():
    assert benchmark_file("probe", "force/protocol~raw/seed~0") == (
        "results/benchmarks/probe/force/protocol~raw/seed~0.tsv"
    )


def test_align_grid_expands_every_cell_in_config_order(tiny):
    plan = AlignPlan.from_config(tiny)
    a = tiny["align"]
    cells = plan.cells()
    assert len(cells) == (
        len(a["corpora"])
        * len(a["variants"])
        * len(a["seeds"])
        * len(a["taus"])
        * len(a["n_train"])
    )
    assert cells[0].startswith(f"{a['corpora'][0]}/{a['variants'][0]}/seed~{a['seeds'][0]}/")
    assert plan.grid("results/align/{corpus}/x")[0] == f"results/align/{a['corpora'][0]}/x"


def test_aligned_edge_refuses_heads_that_are_not_trained(tiny):
    plan = AlignPlan.from_config(tiny)
    with pytest.raises(ValueError, match="not in align.corpora"):
        plan.aligned_edge("no_such_corpus", "sim_paired", "clip128", 0, 0.07, "all")


def test_a_grid_corpus_that_is_not_a_corpus_stops_before_the_plan():
    """The validation the rules run before the plan (`workflow_config.validate_config`) names
    it: the plan builds only from a config whose corpus references resolve."""
    cfg = merged_config()
    cfg["scenes_file"] = str(ROOT / cfg["scenes_file"])
    cfg["align"]["corpora"] = [*cfg["align"]["corpora"], "sim_missing"]
    with pytest.raises(ConfigError, match=r"align\.corpora\[\d+\]: unknown corpus 'sim_missing'"):
        validate_config(cfg, ROOT / "config" / "config.schema.yaml")


def test_every_stage_plan_builds_from_each_shipped_config(default, tiny):
    for cfg in (default, tiny):
        plans = StagePlans.from_config(cfg)
        assert plans.generate.reference_cell() in plans.generate.cells
        assert set(plans.regime.corpora) <= set(cfg["corpora"])
        assert plans.probes.jobs and all(
            f in cfg["probes"]["families"] for f, _ in plans.probes.jobs
        )


def test_the_positive_control_runs_on_the_largest_rho_only_where_there_is_a_curve(default):
    """regime_look_control: the largest rho's corpus, where two or more pool sizes make a
    curve, a control SNR is set and that rho is above 0; none otherwise (the default, with
    one pool size, keeps its budget)."""
    from tacgen_lib.plan.regime import RegimePlan

    def control(**regime) -> list[str]:
        return RegimePlan({**default["regime"], **regime}).control_corpora

    assert default["regime"]["look_control_snr"] is not None
    assert RegimePlan(default["regime"]).control_corpora == []  # one pool size
    assert control(n_pool=[256, 1024], rhos=[1, 0]) == ["sim_natural_r1"]
    assert control(n_pool=[256, 1024], rhos=[0, 0.5]) == ["sim_natural_r05"]
    assert control(n_pool=[256, 1024], rhos=[0]) == []
    assert control(n_pool=[256, 1024], rhos=[]) == []  # no regime corpora at all
    assert control(n_pool=[256, 1024], look_control_snr=None) == []
    plan = RegimePlan({**default["regime"], "n_pool": [256, 1024], "seeds": [0, 1]})
    assert plan.control_files("{corpus}/{seed}") == [
        f"{plan.control_corpora[0]}/0",
        f"{plan.control_corpora[0]}/1",
    ]


def test_every_corpus_gets_vision_and_its_tactile_variants(tiny):
    plans = StagePlans.from_config(tiny)
    edges = plans.features.corpus_feature_edges(tiny)
    for corpus in tiny["corpora"]:
        assert f"results/features/{corpus}/vision.parquet" in edges
    # a corpus only the regime reads gets only the generator's variant
    regime_only = [c for c in plans.regime.corpora if c not in tiny["align"]["corpora"]]
    for corpus in regime_only:
        tactile = [e for e in edges if e.startswith(f"results/features/{corpus}/tactile~")]
        assert tactile == [
            f"results/features/{corpus}/tactile~{tiny['generate']['variant']}.parquet"
        ]


def test_extraction_runs_one_thread_at_low_priority_only_for_natural_corpora(tiny):
    plans = StagePlans.from_config(tiny)
    natural = SimpleNamespace(corpus=plans.regime.corpora[0])
    other = SimpleNamespace(corpus="sim_paired")
    assert plans.features.extraction_threads(natural) == 1
    assert plans.features.extraction_priority(natural) < plans.features.extraction_priority(other)
    assert plans.features.extraction_threads(other) == tiny["features"]["threads"]


def test_pixel_refuses_a_corpus_split_by_object(tiny):
    cfg = copy.deepcopy(tiny)
    by_object = sorted(cfg["splits"]["by_object"])[0]
    cfg["pixel"]["corpora"] = {by_object: {"hardness": "classification"}}
    with pytest.raises(ValueError, match="is split by object"):
        PixelPlan.from_config(cfg)


def test_transfer_views_need_trained_heads(tiny):
    align = AlignPlan.from_config(tiny)
    cfg = copy.deepcopy(tiny)
    cfg["transfer"]["source"] = "sim_null_missing"
    with pytest.raises(ValueError, match="transfer.source"):
        TransferPlan.from_config(cfg, align)
    plan = TransferPlan.from_config(tiny, align)
    target = plan.aligned("target", 0)
    assert "/n~all/" in target, "the transfer corpus's own heads train on all its train rows"


def test_findings_read_only_the_stages_that_run():
    none = findings_inputs(
        policy=False, regime=False, visibility=False, backbones=False, transfer=False, pixel=False
    )
    assert none == {}
    every = findings_inputs(
        policy=True, regime=True, visibility=True, backbones=True, transfer=True, pixel=True
    )
    assert {"policy_summary", "regime", "visibility", "backbones", "transfer", "pixel"} <= set(
        every
    )


def test_the_cost_plan_reads_each_knobs_benchmarks_once():
    cfg = validated("cost_tiny.yaml")
    plan = CostPlan.from_config(cfg, StagePlans.from_config(cfg))
    assert plan.knobs(), "config/cost_tiny.yaml sweeps knobs"
    for knob in plan.knobs():
        inputs = plan.knob_inputs(SimpleNamespace(knob=knob))
        assert len(inputs["benchmarks"]) == len(set(inputs["benchmarks"]))
        assert all(b.startswith("results/") and b.endswith(".tsv") for b in inputs["benchmarks"])
        for run in plan.setting_plan(knob):
            assert set(run["benchmarks"]) <= set(inputs["benchmarks"])


def test_the_cost_modules_are_snakemake_statements_the_parser_compiles(tmp_path):
    cfg = validated("cost_tiny.yaml")
    plan = CostPlan.from_config(cfg, StagePlans.from_config(cfg))
    modules = plan.modules()
    assert len(modules) > 1, "config/cost_tiny.yaml sweeps several settings"
    source = plan.modules_source("PLAN", "STAGES")
    assert source.startswith("# Generated from config cost.knobs by tacgen_lib.plan.cost.")
    for module, (_, rules) in modules.items():
        assert f"\nmodule {module}:\n" in source
        assert f"\n        PLAN.module_config({module!r})\n" in source
        assert f"\nuse rule {', '.join(rules)} from {module} as {module}_*\n" in source
    # Snakemake's parser compiles the text to the workflow's module and use-rule calls: the
    # settings' modules, configs, prefixes and renamed rules, in the plan's order
    smk = tmp_path / "modules.smk"
    smk.write_text(source)
    code, _ = rule_file_python(smk)
    calls: list[tuple[str, dict]] = []
    workflow = SimpleNamespace(
        module=lambda **kw: calls.append(("module", kw)),
        userule=lambda **kw: calls.append(("use rule", kw)) or (lambda rule: None),
    )
    exec(compile(code, str(smk), "exec"), {"workflow": workflow, "PLAN": plan, "STAGES": "s"})
    assert [kind for kind, _ in calls] == ["module", "use rule"] * len(modules)
    for (module, (run, rules)), (_, mod), (_, use) in zip(
        modules.items(), calls[::2], calls[1::2], strict=True
    ):
        assert mod["name"] == module and mod["snakefile"] == "s" and mod["config"] is run.config
        assert mod["replace_prefix"] == run.replace_prefix
        assert use["rules"] == rules and use["from_module"] == module
        assert use["name_modifier"] == f"{module}_*" and use["exclude_rules"] == []
    # a run that sweeps nothing has no module to write
    default = validated()
    empty = CostPlan.from_config(default, StagePlans.from_config(default))
    assert not empty.modules()
    assert all(line.startswith("#") for line in empty.modules_source("P", "S").splitlines())


def test_the_cost_modules_file_is_named_by_its_text_and_written_once(tmp_path):
    path = write_source(tmp_path / "cost_modules", "a\n")
    assert Path(path).is_absolute() and Path(path).read_text() == "a\n"
    os.utime(path, (0, 0))
    assert write_source(tmp_path / "cost_modules", "a\n") == path  # the same text: untouched
    assert Path(path).stat().st_mtime == 0
    other = write_source(tmp_path / "cost_modules", "b\n")
    assert other != path and Path(path).read_text() == "a\n"  # another text: another file
    assert sorted(p.name for p in (tmp_path / "cost_modules").iterdir()) == sorted(
        Path(p).name for p in (path, other)
    )  # no temporary file left
