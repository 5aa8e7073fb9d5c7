"""Every stage's rules, from the config's validation to the report: the main workflow's (the
Snakefile includes this file) and each cost setting's (a module of this file with the setting's
config, rules/cost_common.smk), without what only the main workflow has (rule all, the
preloaded interpreter, the run-time and GPU resources)."""


include: "common.smk"
include: "report_common.smk"


wildcard_constraints:
    corpus="[a-z][a-z0-9_]*",
    shard=r"\d+",


include: "corpus.smk"
include: "preprocess.smk"
include: "features.smk"
include: "align.smk"
include: "generate.smk"
include: "regime.smk"
include: "pixel.smk"
include: "language.smk"
include: "probes.smk"
include: "backbones.smk"
include: "transfer.smk"
include: "policy.smk"
include: "cost.smk"
include: "report.smk"
