"""BLAS thread limits for the probes' many small solves.

lbfgs on probe-sized problems makes thousands of tiny BLAS/LAPACK calls (inside scipy's
L-BFGS-B): with 2 BLAS threads on a loaded 2-core machine each call waits for a busy core,
an order of magnitude slower than one thread. Logistic fits, the ridge deletion paths and the PCG
set-up therefore run single-threaded.
"""

from __future__ import annotations

from contextlib import AbstractContextManager

from threadpoolctl import ThreadpoolController

__all__ = ["single_blas_thread"]

_BLAS = ThreadpoolController()


def single_blas_thread() -> AbstractContextManager:
    """Context manager: BLAS/LAPACK limited to one thread for the block it guards (the many
    small products of lbfgs, the deletion paths and the PCG set-up)."""
    return _BLAS.limit(limits=1)
