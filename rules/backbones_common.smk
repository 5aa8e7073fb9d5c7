"""Backbone families' names (tacgen_lib.plan.families): the paths the rules of
rules/backbones.smk read."""

from tacgen_lib.features.settings import backbone_image_size
from tacgen_lib.plan.families import FAMILY_PROBE

FAMILIES = PLANS.families.settings
OWN_FAMILIES = PLANS.families.own
FAMILY_VARIANT = PLANS.families.variant  # the tactile frames the probes read
FAMILY_CORPORA = PLANS.families.corpora
_PROBE_SEED = PROBES["seeds"][0]
#: the (probe family, protocol) jobs a family is judged on
FAMILY_JOBS = PLANS.families.jobs
# the main family's rows are the probes stage's own headline rows when it probes every
# (probe family, protocol) asked here (nothing is computed twice); else family_probe makes them
MAIN_FROM_PROBES = PLANS.families.main_from_probes
COMPUTED_FAMILIES = PLANS.families.computed

if PLANS.families.on:
    TARGETS += ["results/report/backbones/table.html"]
    EDGES += PLANS.families.edges()
