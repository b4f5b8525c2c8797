"""Compiled scalar helpers of the model shared by the compiled loops (the observer's kernel, the simulators)."""

from __future__ import annotations

import numba


@numba.njit(cache=True, nogil=True)
def sign(x):
    """sgn(x) of Eqs. 15-17: +1, -1, or 0 at exactly 0 (a wheel at rest has no Coulomb friction term)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0
