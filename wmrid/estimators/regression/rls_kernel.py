"""The compiled recursive-least-squares kernel (:func:`rls_kernel`, numba) of :mod:`wmrid.estimators.regression.rls`:
the
covariance-form update with forgetting over the IDIM regression's rows, a Cholesky with a minimum pivot, the history and
the per-batch scores the jackknife needs."""

from __future__ import annotations

import math

import numpy as np

from wmrid.core.jit import kernel
from wmrid.estimators.regression.idim_rows import ROW_LAYOUT

#: The recursion starts when every Cholesky pivot^2 of the equilibrated information exceeds this.
INIT_PIVOT = 1e-4


# (row, phi column, feature index) of each regressor entry, a compile-time constant of the kernel.
_ROW_COL_FEAT = np.array(ROW_LAYOUT, dtype=np.int64)


@kernel
def _cholesky_min_pivot(r, work):
    """Cholesky of the diagonally equilibrated r (p, p) into work; smallest pivot^2, or -1 on failure."""
    n = r.shape[0]
    for i in range(n):
        if r[i, i] <= 0.0:
            return -1.0
    for i in range(n):
        for j in range(n):
            work[i, j] = r[i, j] / math.sqrt(r[i, i] * r[j, j])
    smallest = 1e300
    for j in range(n):
        s = work[j, j]
        for k in range(j):
            s -= work[j, k] * work[j, k]
        if s <= 0.0:
            return -1.0
        smallest = min(smallest, s)
        d = math.sqrt(s)
        work[j, j] = d
        for i in range(j + 1, n):
            s = work[i, j]
            for k in range(j):
                s -= work[i, k] * work[j, k]
            work[i, j] = s / d
    return smallest


@kernel
def _invert_equilibrated(rinfo, work, pm):
    """pm = rinfo^-1 from the Cholesky factor L (in work) of D^-1 rinfo D^-1, D = sqrt(diag rinfo)."""
    p = rinfo.shape[0]
    linv = np.zeros((p, p))
    for i in range(p):
        linv[i, i] = 1.0 / work[i, i]
        for j in range(i):
            s = 0.0
            for c in range(j, i):
                s -= work[i, c] * linv[c, j]
            linv[i, j] = s / work[i, i]
    for a in range(p):
        for b in range(p):
            s = 0.0
            for c in range(max(a, b), p):
                s += linv[c, a] * linv[c, b]
            pm[a, b] = s / math.sqrt(rinfo[a, a] * rinfo[b, b])


@kernel
def rls_kernel(
    features,
    tau,
    scale,
    caster,
    lam,
    init_pivot,
    segment,
    blk_a,
    blk_c,
    stride,
    block_len,
    hist_idx,
    hist_phi,
    hist_p,
    hist_w2,
    stats,
    scores,
):
    """Covariance-form RLS over all samples (see the module docstring), in column-scaled coordinates.

    p, the size of phi, is that of ``scale``: 8, plus the caster parameters.
    features (N, 8 + q) unscaled regression features (:data:`wmrid.estimators.regression.idim_rows.FEATURE_NAMES`, then
    the q caster
    columns); tau (N, 2) N m; scale (p,) column scales d (phi_s = d phi); caster (q, 3) int64 rows (feature
    index, phi index, pattern) of each caster column, which adds to phi's entry in row 1 and pattern x itself
    in row 2 (:func:`wmrid.estimators.regression.idim_rows.rows_from_features`; (0, 3) without caster drag); lam the
    forgetting factor;
    init_pivot the start test (:data:`INIT_PIVOT`); segment (N,) the block in [0, len(blk_a)) of each sample (the
    jackknife's sub-segments, :func:`wmrid.estimators.regression.idim.sub_segments`);
    block_len samples per batch of the batch means.  Filled in place:

    * blk_a (B, p, p), blk_c (B, p): per-block scaled X^T X and X^T y;
    * after every ``stride`` samples and at the last one: hist_idx (m,) the sample index, hist_phi (m, p)
      the scaled estimate, hist_p (m, p, p) P, hist_w2 (m,) sum lambda^(2(n-k)) (NaN before the start);
    * stats (6,): start index (-1: never), trace cap, capped steps, local mean square a priori error of
      wheel 1 and 2 (N m^2, lambda-weighted), number of complete batches;
    * scores (p + 1, p): rows 0..p-1 the sum of z_b z_b^T, row p the sum of z_b, over the batches, z_b the
      sum over a batch of the scores x_k^T e_k (a priori errors).

    Returns phi_s (p,) and P (p, p) at the last sample.
    """
    n = features.shape[0]
    p = scale.shape[0]
    h = np.zeros((2, p))
    phi = np.zeros(p)
    pm = np.zeros((p, p))
    rinfo = np.zeros((p, p))
    rvec = np.zeros(p)
    work = np.zeros((p, p))
    ph = np.zeros((p, 2))
    kg = np.zeros((p, 2))
    e = np.zeros(2)
    ssq = np.zeros(2)
    wsum = 0.0
    w2 = 0.0
    zb = np.zeros(p)
    block_count = 0
    n_batches = 0
    init = -1
    trace_cap = 0.0
    capped = 0
    m = 0
    for k in range(n):
        for i in range(2):
            for j in range(p):
                h[i, j] = 0.0
        for c in range(_ROW_COL_FEAT.shape[0]):
            col = _ROW_COL_FEAT[c, 1]
            h[_ROW_COL_FEAT[c, 0], col] = features[k, _ROW_COL_FEAT[c, 2]] / scale[col]
        for c in range(caster.shape[0]):
            col = caster[c, 1]
            v = features[k, caster[c, 0]] / scale[col]
            h[0, col] += v
            h[1, col] += caster[c, 2] * v
        y0 = tau[k, 0]
        y1 = tau[k, 1]
        g = segment[k]
        for a in range(p):
            blk_c[g, a] += h[0, a] * y0 + h[1, a] * y1
            for b in range(p):
                blk_a[g, a, b] += h[0, a] * h[0, b] + h[1, a] * h[1, b]
        w2 = lam * lam * w2 + 1.0
        if init < 0:
            for a in range(p):
                rvec[a] = lam * rvec[a] + h[0, a] * y0 + h[1, a] * y1
                for b in range(p):
                    rinfo[a, b] = lam * rinfo[a, b] + h[0, a] * h[0, b] + h[1, a] * h[1, b]
            if _cholesky_min_pivot(rinfo, work) >= init_pivot:
                _invert_equilibrated(rinfo, work, pm)
                for a in range(p):
                    s = 0.0
                    for b in range(p):
                        s += pm[a, b] * rvec[b]
                    phi[a] = s
                    trace_cap += pm[a, a]
                init = k
        else:
            for i in range(2):
                s = tau[k, i]
                for a in range(p):
                    s -= h[i, a] * phi[a]
                e[i] = s
                for a in range(p):
                    s = 0.0
                    for b in range(p):
                        s += pm[a, b] * h[i, b]
                    ph[a, i] = s
            s00 = lam
            s01 = 0.0
            s11 = lam
            for a in range(p):
                s00 += h[0, a] * ph[a, 0]
                s01 += h[0, a] * ph[a, 1]
                s11 += h[1, a] * ph[a, 1]
            det = s00 * s11 - s01 * s01
            i00 = s11 / det
            i01 = -s01 / det
            i11 = s00 / det
            for a in range(p):
                kg[a, 0] = ph[a, 0] * i00 + ph[a, 1] * i01
                kg[a, 1] = ph[a, 0] * i01 + ph[a, 1] * i11
                phi[a] += kg[a, 0] * e[0] + kg[a, 1] * e[1]
            trace = 0.0
            for a in range(p):
                for b in range(a, p):
                    v = pm[a, b] - kg[a, 0] * ph[b, 0] - kg[a, 1] * ph[b, 1]
                    pm[a, b] = v
                    pm[b, a] = v
                trace += pm[a, a]
            if lam < 1.0:
                if trace <= lam * trace_cap:
                    for a in range(p):
                        for b in range(p):
                            pm[a, b] /= lam
                else:
                    capped += 1
            wsum = lam * wsum + 1.0
            for i in range(2):
                ssq[i] = lam * ssq[i] + e[i] * e[i]
            for a in range(p):
                zb[a] += h[0, a] * e[0] + h[1, a] * e[1]
            block_count += 1
            if block_count == block_len:
                for a in range(p):
                    scores[p, a] += zb[a]
                    for b in range(p):
                        scores[a, b] += zb[a] * zb[b]
                for a in range(p):
                    zb[a] = 0.0
                block_count = 0
                n_batches += 1
        if (k + 1) % stride == 0 or k == n - 1:
            hist_idx[m] = k
            for a in range(p):
                hist_phi[m, a] = phi[a] if init >= 0 else np.nan
                for b in range(p):
                    hist_p[m, a, b] = pm[a, b] if init >= 0 else np.nan
            hist_w2[m] = w2 if init >= 0 else np.nan
            m += 1
    stats[0] = init
    stats[1] = trace_cap
    stats[2] = capped
    stats[3] = ssq[0] / wsum if wsum > 0 else np.nan
    stats[4] = ssq[1] / wsum if wsum > 0 else np.nan
    stats[5] = n_batches
    return phi, pm
