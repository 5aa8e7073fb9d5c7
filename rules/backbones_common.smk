"""Backbone families' names (tacgen_lib.plan.families): the paths the rules of
rules/backbones.smk read."""

from tacgen_lib.features.settings import backbone_image_size
from tacgen_lib.plan.families import FAMILY_PROBE

if PLANS.families.on:
    TARGETS += ["results/report/backbones/table.html"]
    EDGES += PLANS.families.edges()
