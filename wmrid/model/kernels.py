"""Compiled scalar helpers of the model shared by the compiled loops (the observer's kernel, the simulators)."""

from __future__ import annotations

import numpy as np

from wmrid.core.jit import kernel


def plain(a: object, dtype: type = np.float64) -> np.ndarray:
    """``a`` as a C-contiguous, writable array of ``dtype`` (copied only when it is not one already): the one type
    the compiled kernels are compiled for.  numba compiles a kernel once per argument type, and a read-only or a
    strided array is another type: a log's read-only arrays had the observer compiled five times on a cold cache
    (about 4 s each)."""
    return np.require(a, dtype=dtype, requirements=("C", "W"))


@kernel
def sign(x):
    """sgn(x) of Eqs. 15-17: +1, -1, or 0 at exactly 0 (a wheel at rest has no Coulomb friction term)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0
