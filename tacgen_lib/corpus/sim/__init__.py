"""MuJoCo-simulated visuo-tactile corpus: scenes that declare their effects.

Modules: `scenes` (effect vocabulary, validation, MJCF compilation), `physics` (objects and
the MuJoCo press), `tactile` (DIGIT-like frames from gel indentation), `corpus` (paired,
appearance-controlled and null corpora, sharded), `grasp` (the grasp_lift policy scene).

Offscreen RGB rendering needs an OpenGL platform chosen before `mujoco` is first imported;
we default to headless EGL (Mesa llvmpipe on CPU machines) unless MUJOCO_GL is already set.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
