"""Config validation and the helpers every rule file uses."""

import os
import re
from pathlib import Path

from tacgen_lib.features.settings import pretraining_corpora
from tacgen_lib.generate.regime_sets import natural_grid_ends, regime_corpora
from tacgen_lib.io.config import load_yaml
from tacgen_lib.workflow_config import validate_config
from tacgen_lib.io.imports import code_inputs
from tacgen_lib.io.run_compare import DECISIONS
from tacgen_lib.report_pages import category
from tacgen_lib.runtime.device import device_spec

#: this workflow's own tree (the repository): where its schema, scripts and library live, also
#: when another workflow uses it as a module (`workflow.basedir` is then that workflow's
#: directory, not this one)
WORKFLOW_ROOT = Path(str(workflow.current_basedir)).parent

# validate_config joins the regime's natural corpora (one per rho of config regime) to the
# corpora first, so each is checked like any declared corpus
_setting = (config.get("cost") or {}).get("setting")
validate_config(
    config,
    WORKFLOW_ROOT / "config" / "config.schema.yaml",
    source=(
        f"cost.knobs.{_setting['knob']} = {_setting['label']} over " if _setting else ""
    )
    + (" + ".join(str(f) for f in workflow.configfiles) or "config"),
)
SCENES = (
    load_yaml(config["scenes_file"]) if os.path.exists(config["scenes_file"]) else {}
)
CORPORA = config["corpora"]
#: config device (cpu | cuda | auto), with +tf32 where config allow_tf32 lets a GPU use it:
#: where every torch job computes, passed in its params (tacgen_lib.runtime.device.torch_device
#: reads it; cpu is bit-identical to a CPU-only run)
DEVICE = device_spec(config["device"], config["allow_tf32"])
#: config probes without the families and seeds the rules expand: what every rule that fits
#: probes passes on (tacgen_lib.probes.settings.ProbeSettings.from_config reads it)
PROBE_SETTINGS = {
    k: v for k, v in config["probes"].items() if k not in ("families", "seeds")
}
#: config transfer (tacgen_lib.probes.transfer): the second sensor's corpus, None for no stage
TRANSFER = config.get("transfer") or {}
TRANSFER_CORPUS = TRANSFER.get("corpus")
SIM_CORPORA = sorted(n for n, c in CORPORA.items() if c["kind"] == "simulated")
REAL_CORPORA = sorted(n for n, c in CORPORA.items() if c["kind"] != "simulated")
NOTHING = "(?!x)x"  # a regex matching no name (no corpus of that kind)
# Snakemake starts ready jobs of higher priority first and does not look at what waits for a
# job. The policy stage is the DAG's last long chain (features -> alignment heads -> palpate ->
# train -> roll out -> aggregate): its rules go first, or the chain starts after the probes and
# leaves a core idle at the end of a run.
CHAIN_PRIORITY = 1
# The vision backbone's pretraining, a long one-thread job that every job reading V waits for,
# goes before everything else that is ready: started late, it ran alone at the end of the
# corpus stage with a core idle. The latent generators' training (long one-thread jobs) goes
# with the chain: started last, one ran alone with a core idle while the regime's two-thread
# jobs waited for both cores.
FIRST_PRIORITY = 2


def extraction_threads(wildcards):
    """An extraction job's threads: config features.threads, but one for the regime's natural
    corpora. Their features feed only the regime's jobs, which run last, never the policy
    chain; one thread keeps its core busy (two keep ~1.45 of 2 cores busy), and a one-thread
    job can run beside a long one-thread job where a two-thread job waits for both cores.
    """
    return 1 if wildcards.corpus in NATURAL_GRID else config["features"]["threads"]


def extraction_priority(wildcards):
    """The policy chain's priority (CHAIN_PRIORITY), except for the regime's natural corpora."""
    return 0 if wildcards.corpus in NATURAL_GRID else CHAIN_PRIORITY


def pretraining_frames(modality, spec):
    """The frame edges a backbone (a BackboneSpec) learns from: each corpus of
    features.pretrain.corpus, RGB or its tactile variant; none for a checkpoint or the random
    init, which read no frames and so wait for no corpus."""
    if not spec.pretrains(int(config["features"]["pretrain"]["epochs"])):
        return []
    return [
        backbone_frames(modality, c)
        for c in pretraining_corpora(config["features"]["pretrain"])
    ]


def one_of(names):
    """Wildcard constraint accepting exactly these names."""
    return "|".join(map(re.escape, names)) if names else NOTHING


def none_of(names):
    """Wildcard constraint accepting any path segment except these names (no ruleorder: a
    ruleorder breaks the cost sweep's modules that import only one of its rules)."""
    return f"(?!(?:{one_of(names)})(?![^/]))[^/]+"


def imports_of(script):
    """Code inputs of a rule: the tacgen_lib modules its script reaches through imports.

    Derived from the script's source (tacgen_lib.io.imports), so editing a module reruns exactly
    the jobs whose scripts reach it, however indirectly.
    """
    base = WORKFLOW_ROOT
    return code_inputs(
        base / "workflow" / "scripts" / f"{script}.py", base / "tacgen_lib"
    )


def corpus_edge(corpus, what="samples"):
    return f"results/corpus/{corpus}/{what}.parquet"


# Each stage's .smk appends what it keeps: TARGETS feed `rule all`, EDGES the edge manifest.
TARGETS = ["results/corpus/manifest.parquet", "results/corpus/splits.parquet"]
EDGES = ["results/corpus/manifest.parquet", "results/corpus/splits.parquet"]
for _corpus in sorted(CORPORA):
    EDGES += [corpus_edge(_corpus), corpus_edge(_corpus, "sensors")]


def feature_edge(corpus, modality, variant=None):
    """The frozen-feature edge of a corpus: vision, or tactile for one preprocessing variant."""
    if modality == "vision":
        return f"results/features/{corpus}/vision.parquet"
    return f"results/features/{corpus}/tactile~{variant}.parquet"


def backbone_frames(modality, corpus):
    """The frames a modality's backbone sees: RGB from the corpus edge, tactile_proc per variant."""
    if modality == "vision":
        return corpus_edge(corpus)
    return f"results/preprocess/{corpus}/{config['features']['pretrain']['variant']}.parquet"
