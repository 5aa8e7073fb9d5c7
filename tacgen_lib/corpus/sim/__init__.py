"""MuJoCo-simulated visuo-tactile corpus: scenes that declare their effects.

Modules: `scenes` (effect vocabulary, validation, MJCF compilation), `physics` (objects and
the MuJoCo press), `tactile` (DIGIT-like frames from gel indentation), `render` (one sample's
RGB and tactile frames), `corpus` (paired, appearance-controlled and null corpora, sharded). The grasp_lift scene is the policy
stage's (tacgen_lib.policy.task).

Offscreen RGB rendering needs an OpenGL platform chosen before `mujoco` is first imported;
we default to headless EGL (Mesa llvmpipe on CPU machines) unless MUJOCO_GL is already set.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
