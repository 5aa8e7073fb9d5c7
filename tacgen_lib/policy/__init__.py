"""Policy stage: a grasp-lift-hold task where touch is needed (docs/policy.md).

Modules: settings (PolicySettings), task (episodes, grip-force window, physics-only lift),
palpation (the observation phase: RGB + both pads' tactile frames), oracle (privileged
controller and the vision-only ceiling), bc (behaviour-cloning MLP and its conditions),
evaluate (paired bootstrap, failure modes, capacity sweep, grip-force regression).
"""
