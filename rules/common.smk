"""Config validation, every stage's plan (tacgen_lib.plan) and the path helpers every rule file
uses."""

from functools import partial
from pathlib import Path

from tacgen_lib.io.config import load_yaml
from tacgen_lib.io.run_compare import DECISIONS
from tacgen_lib.plan.paths import (
    corpus_edge,
    feature_edge,
    none_of,
    one_of,
    script_imports,
)
from tacgen_lib.plan.priorities import CHAIN_PRIORITY, FIRST_PRIORITY
from tacgen_lib.plan.stages import StagePlans
from tacgen_lib.report_pages import category
from tacgen_lib.runtime.device import device_spec
from tacgen_lib.workflow_config import validate_config

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
    load_yaml(config["scenes_file"]) if Path(config["scenes_file"]).exists() else {}
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
TRANSFER = config["transfer"]
TRANSFER_CORPUS = TRANSFER.get("corpus")
SIM_CORPORA = sorted(n for n, c in CORPORA.items() if c["kind"] == "simulated")
REAL_CORPORA = sorted(n for n, c in CORPORA.items() if c["kind"] != "simulated")
#: the plan of every stage (each checks its part of the config as it is built)
PLANS = StagePlans.from_config(config)
#: a rule's code inputs: the tacgen_lib modules its script reaches (tacgen_lib.io.imports)
imports_of = partial(script_imports, WORKFLOW_ROOT)

# Each stage's .smk appends what it keeps: TARGETS feed `rule all`, EDGES the edge manifest.
TARGETS = ["results/corpus/manifest.parquet", "results/corpus/splits.parquet"]
EDGES = ["results/corpus/manifest.parquet", "results/corpus/splits.parquet"]
for _corpus in sorted(CORPORA):
    EDGES += [corpus_edge(_corpus), corpus_edge(_corpus, "sensors")]
