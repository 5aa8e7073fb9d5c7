"""How far two computations of the same floats may differ (docs/tests.md, "The same tests on
other CPU kernels"): the same arithmetic in another order -- another kernel, batch shape or
thread count, or a saved and reloaded model, whose weights may send torch to another kernel
path -- moves a result by rounding only, so such results are compared within a bound derived
from the dtype's eps and the computation's size. Bit identity stays for bytes written twice
from the same arrays and for one computation run twice. (A plain module: pytest puts tests/ on
sys.path.)"""

from __future__ import annotations

import numpy as np


def reordered_sum_atol(ref, *, terms: int, depth: int) -> float:
    """The absolute tolerance between `ref` (an array or tensor) and another computation of
    it whose sums may run in another order: each value comes through `depth` chained layers,
    each a sum of at most `terms` products. Rounding errors of either sign make a sum of n
    terms in another order move by about sqrt(n) eps of its size, taken as max(1, max |ref|)
    (the activations of normalised layers stay near 1), and a chain's moves add the same way:
    sqrt(depth x terms) x eps x max(1, max |ref|), as `PASS_DRIFT` in
    tests/generate/test_generate.py."""
    arr = np.asarray(ref.detach().cpu().numpy() if hasattr(ref, "detach") else ref)
    eps = float(np.finfo(arr.dtype).eps)
    return float(np.sqrt(depth * terms)) * eps * max(1.0, float(np.abs(arr).max()))
