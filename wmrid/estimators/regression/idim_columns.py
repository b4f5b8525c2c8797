"""The IDIM regression's unfiltered columns, written sample by sample into the zero-phase filter's buffer (compiled:
:func:`wmrid.estimators.regression.idim_rows.idim_regression` filters them side by side, a row per sample, and numpy
writing one column at a time into that layout took as long as the filter itself)."""

from __future__ import annotations

from wmrid.core.jit import kernel
from wmrid.model.kernels import sign


@kernel
def raw_columns_into(eta, tau, out):  # pragma: no cover - compiled; tests/unit/estimators/test_idim.py compares it
    """out (n, >= 8): per sample eta_1, eta_2, eta_1 eta_2 - eta_2^2, eta_1 eta_2 - eta_1^2 (rad/s, rad^2/s^2),
    sgn eta_1, sgn eta_2 (0 at a speed of 0, as numpy's sign), tau_1, tau_2, from eta (n, 2) rad/s and tau (n, 2)
    (finite); its columns past the eighth are left as they are.  The same operations as numpy's, value by value."""
    for i in range(eta.shape[0]):
        e1 = eta[i, 0]
        e2 = eta[i, 1]
        out[i, 0] = e1
        out[i, 1] = e2
        out[i, 2] = e1 * e2 - e2 * e2
        out[i, 3] = e1 * e2 - e1 * e1
        out[i, 4] = sign(e1)
        out[i, 5] = sign(e2)
        out[i, 6] = tau[i, 0]
        out[i, 7] = tau[i, 1]
