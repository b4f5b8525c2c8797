"""The compiled twin of :func:`wmrid.estimators.observer.step.observer_step`, run over a log chunk by chunk.

Same arithmetic as the readable step (tests check agreement to 1e-12), plus what the reports need,
accumulated on the fly so memory does not grow with the log: a decimated history and per-block sums
of the least-squares normal equations for the uncertainty (:mod:`wmrid.estimators.uncertainty`).
"""

from __future__ import annotations

import math

import numpy as np

from wmrid.core.jit import kernel
from wmrid.model.dynamics import DRAG_SPEED
from wmrid.model.kernels import sign

KIND_PAPER = 0
KIND_GENERAL = 1
KIND_CASTER = 2  # general plus the caster-drag columns -sgn(eta_1 + eta_2), -sgn(eta_1 - eta_2)
#: general plus two columns per caster of known position (wmrid.model.dynamics.caster_columns), and two per caster and
#: load signal of the wheel+caster+load model (the kernel's ``load`` codes; v' and w' filtered by _derivative_inputs)
KIND_CASTER_GEOMETRY = 3
#: The distinct steps h whose coefficients (:func:`foh`, :func:`_substep_weights`) :func:`observer_chunk` keeps.
STEP_CACHE = 8
#: Samples whose regressor :func:`observer_chunk` makes at a time (:func:`_regressor_rows`).
REGRESSOR_ROWS = 512


@kernel
def _regressor_rows(out, eta, eta_sign, tau, start, kind, geom, load):
    """The filters' per-sample inputs g (:func:`wmrid.model.dynamics.filter_regressor`) of the samples start ..
    start + m - 1 into ``out`` (m, p), a row each.

    eta (c, 2) rad/s: the measured speeds; eta_sign (c, 2) rad/s: the speeds the sign columns and the casters' drag
    directions are taken from (:mod:`wmrid.estimators.sign_speed`); tau (c, 2).  load (L,) int64: kind 3's load
    signals, codes into :data:`wmrid.model.dynamics.LOAD_SIGNALS` (0 dv, 1 w2, 2 vw, 3 dw); the columns of dv and dw
    hold their multiplier (see :func:`_derivative_inputs`).  Rows at a time: a compiled call takes and drops a
    reference count per array it is passed (two atomic operations each), a third of the replay's time when this was
    called per sample."""
    r, b = (geom[0], geom[1]) if kind == KIND_CASTER_GEOMETRY else (0.0, 1.0)  # geom = [r, b, x_1, y_1, ...]
    nk = (len(geom) - 2) // 2
    nl = len(load)
    for row in range(out.shape[0]):
        i = start + row
        e1, e2, s1, s2 = eta[i, 0], eta[i, 1], eta_sign[i, 0], eta_sign[i, 1]
        out[row, 0] = tau[i, 0]
        out[row, 1] = tau[i, 1]
        out[row, 2] = e2 * e2 - e1 * e2
        out[row, 3] = e1 * e1 - e1 * e2
        out[row, 4] = -e1
        out[row, 5] = -e2
        if kind == KIND_PAPER:
            out[row, 6] = -1.0
            continue
        out[row, 6] = -sign(s1)
        out[row, 7] = -sign(s2)
        if kind == KIND_CASTER:
            out[row, 8] = -sign(s1 + s2)
            out[row, 9] = -sign(s1 - s2)
        elif kind == KIND_CASTER_GEOMETRY:
            v = 0.5 * r * (e1 + e2)
            w = r / (2.0 * b) * (e1 - e2)
            vs = 0.5 * r * (s1 + s2)  # the drag's direction from the sign speeds, its load signals from the measured
            ws = r / (2.0 * b) * (s1 - s2)
            for k in range(nk):
                x, y = geom[2 + 2 * k], geom[3 + 2 * k]
                ux = vs - ws * y
                uy = ws * x
                norm = math.sqrt(ux * ux + uy * uy + DRAG_SPEED * DRAG_SPEED)
                cv = 0.5 * r * ux / norm
                cw = r / (2.0 * b) * (x * uy - y * ux) / norm
                out[row, 8 + 2 * k] = -cv
                out[row, 9 + 2 * k] = -cw
                for j in range(nl):
                    code = load[j]
                    s = 1.0  # dv, dw: the multiplier of the derivative
                    if code == 1:
                        s = w * w
                    elif code == 2:
                        s = v * w
                    col = 8 + 2 * nk + 2 * (k * nl + j)
                    out[row, col] = -cv * s
                    out[row, col + 1] = -cw * s


@kernel
def _derivative_inputs(gin, g_prev, g, row, b0, b1, h, de1, de2, geom, load):
    """Overwrite the filter input of the columns c(eta) phi' (load codes 0: phi = v, 3: phi = w) over a step of h s
    with phi' (b0 c_a + b1 c_b) / h, c_a in g_prev (p,), c_b in g[row] (g (m, p): :func:`_regressor_rows`).  de1, de2:
    h times the wheel speeds' rate of change over the PREVIOUS step, rad/s (the caller keeps that rate;
    :data:`wmrid.model.dynamics.DERIVATIVE_LAG`): the change over this step would carry this sample's speed noise,
    which the prediction error carries too, and the two would correlate.  For load signals only (L > 0)."""
    nl = len(load)
    r, b = geom[0], geom[1]
    dv = 0.5 * r * (de1 + de2) / h
    dw = r / (2.0 * b) * (de1 - de2) / h
    nk = (len(geom) - 2) // 2
    for k in range(nk):
        for j in range(nl):
            code = load[j]
            if code == 0 or code == 3:
                d = dv if code == 0 else dw
                col = 8 + 2 * nk + 2 * (k * nl + j)
                gin[col] = d * (b0 * g_prev[col] + b1 * g[row, col])
                gin[col + 1] = d * (b0 * g_prev[col + 1] + b1 * g[row, col + 1])


@kernel
def foh(x):
    a = math.exp(-x)
    if x < 0.1:
        phi0 = 0.0
        term = 1.0
        for j in range(12):
            phi0 += term / (j + 2)
            term *= -x / (j + 1)
        e1 = 0.0
        term = 1.0
        for j in range(12):
            e1 += term / (j + 1)
            term *= -x / (j + 1)
    else:
        phi0 = (1.0 - a * (1.0 + x)) / (x * x)
        e1 = -math.expm1(-x) / x
    return a, phi0, e1 - phi0


@kernel
def _substep_weights(x, h, m):
    """(c0, c1): the filter input over a step of h s (x = k h) of a torque held over m equal sub-steps at
    values interpolated linearly from tau_n (sub-step 0) towards tau_{n+1}: sum_j (1 - j/m, j/m) W_j,
    W_j = h int over the sub-step of exp(-x v) dv (v = remaining fraction of the step)."""
    c0 = 0.0
    c1 = 0.0
    width = -math.expm1(-x / m) / x if x > 0.0 else 1.0 / m
    for j in range(m):
        w_j = h * math.exp(-x * (1.0 - (j + 1.0) / m)) * width
        c0 += (1.0 - j / m) * w_j
        c1 += (j / m) * w_j
    return c0, c1


@kernel
def observer_chunk(
    t,
    eta,
    eta_sign,
    tau,
    offset,
    kind,
    hold,
    k,
    st,
    w,
    g_prev,
    theta,
    gamma,
    gamma_inv,
    hist_idx,
    hist_theta,
    hist_e,
    hist_gamma,
    block_end,
    blk_a,
    blk_c,
    blk_uu,
    blk_ee,
    cursor,
    geom,
    load,
):
    """Advance the estimator over one chunk of samples; every state array is updated in place.

    t (c,) s, eta and tau (c, 2): samples with global indices offset .. offset + c - 1 (offset >= 1; the
    first sample of the log is the initial state); eta_sign (c, 2) rad/s: the speeds the sign-like columns are
    taken from (:mod:`wmrid.estimators.sign_speed`; eta itself for none).  kind 0 paper / 1 general / 2 general
    with caster drag.
    hold: how the torque columns of g vary between samples: -1 linearly like the others (foh); 0 held
    from each sample to the next (zoh); f > 0 held by a controller running at f Hz, round(h f) sub-steps
    per step, whose unlogged
    values lie on the line between the logged ones (see :func:`_substep_weights`).
    st (9,) = [t_prev, eta_prev (2), eta_hat (2), xi_hat (2), eta's rate of change over the previous step (2)]; w,
    g_prev (p,);
    theta (2, p) unconstrained
    estimate; gamma, gamma_inv (p, p), gamma_inv symmetric (as the observer starts it, and keeps it).
    hist_idx (m,) increasing global sample indices to record into hist_theta (m, 2, p), hist_e (m, 2)
    (prior prediction error, rad/s), hist_gamma (m, p, p).  block_end (J,) increasing global indices, the
    last one n - 1: block j sums the steps ending at samples in (block_end[j-1], block_end[j]]:
    blk_a (J, p, p) += h w^T w, blk_c (J, 2, p) += h u_i w, blk_uu (J, 2) += h u_i^2, blk_ee (J, 2) += h e_i^2,
    with u = e - xi_hat + w theta the filtered velocity the estimator regresses on.
    cursor (2,) int64 = [next history slot, current block].
    geom (q,) float64: the caster geometry [r, b, x_1, y_1, ...] of kind 3 (empty otherwise); load (L,) int64: its
    load signals (:func:`_regressor_rows`; empty for none).
    """
    c = t.shape[0]
    p = theta.shape[1]
    m = hist_idx.shape[0]
    # the step's coefficients depend on h alone, and a log has a handful of distinct steps: those of the last
    # STEP_CACHE steps seen are kept (the same values as computed afresh: foh's series costs 24 divisions a sample)
    cached_h = np.full(STEP_CACHE, np.nan)
    cached = np.empty((STEP_CACHE, 5))
    slot = 0
    nl = len(load)
    g = np.empty((min(REGRESSOR_ROWS, c), p))  # the regressor of the next REGRESSOR_ROWS samples (_regressor_rows)
    gin = np.empty(p)
    pw = np.empty(p)
    e_prior = np.empty(2)
    eta_hat = st[3:5]
    xi_hat = st[5:7]
    hi = cursor[0]
    bj = cursor[1]
    for i in range(c):
        n_i = offset + i
        h = t[i] - st[0]
        q = 0
        while q < STEP_CACHE and cached_h[q] != h:
            q += 1
        if q == STEP_CACHE:  # not seen lately: computed, and kept in place of the oldest
            q = slot
            slot = (slot + 1) % STEP_CACHE
            cached_h[q] = h
            cached[q, 0], cached[q, 1], cached[q, 2] = foh(k * h)
            if hold > 0.0:
                cached[q, 3], cached[q, 4] = _substep_weights(k * h, h, max(1, round(h * hold)))
        a = cached[q, 0]
        b0 = h * cached[q, 1]
        b1 = h * cached[q, 2]
        e1 = eta[i, 0]
        e2 = eta[i, 1]
        row = i % REGRESSOR_ROWS
        if row == 0:
            _regressor_rows(g[: min(REGRESSOR_ROWS, c - i)], eta, eta_sign, tau, i, kind, geom, load)
        # the input of the filters over the step: first-order hold, the torques held when zoh
        for j in range(p):
            gin[j] = b0 * g_prev[j] + b1 * g[row, j]
        if hold == 0.0:
            gin[0] = (b0 + b1) * g_prev[0]
            gin[1] = (b0 + b1) * g_prev[1]
        elif hold > 0.0:
            gin[0] = cached[q, 3] * g_prev[0] + cached[q, 4] * g[row, 0]
            gin[1] = cached[q, 3] * g_prev[1] + cached[q, 4] * g[row, 1]
        if nl > 0:
            _derivative_inputs(gin, g_prev, g, row, b0, b1, h, h * st[7], h * st[8], geom, load)
        # (27) w and (26) eta_hat with theta held over the step
        for j in range(p):
            w[j] = a * w[j] + gin[j]
        for r in range(2):
            gt = 0.0
            for j in range(p):
                gt += theta[r, j] * gin[j]
            eta_hat[r] = a * eta_hat[r] + gt + k * (b0 * st[1 + r] + b1 * eta[i, r])
            xi_hat[r] = a * xi_hat[r]  # (30)
        e_prior[0] = e1 - eta_hat[0]
        e_prior[1] = e2 - eta_hat[1]
        # (33), and (34) solved exactly by Sherman-Morrison
        for r in range(p):
            s = 0.0
            for j in range(p):
                s += gamma_inv[r, j] * w[j]
            pw[r] = s
        den = 1.0 / h
        for r in range(p):
            den += w[r] * pw[r]
        while block_end[bj] < n_i:
            bj += 1
        for r in range(p):
            wr = h * w[r]
            for j in range(p):
                dw = wr * w[j]
                gamma[r, j] += dw
                blk_a[bj, r, j] += dw
        # gamma_inv is symmetric, and so is its change (pw_r pw_j = pw_j pw_r): each entry above the diagonal is
        # updated once and averaged with its mirror image, the same value (0.5 (v + v), as the readable step does)
        for r in range(p):
            gamma_inv[r, r] -= pw[r] * pw[r] / den
            for j in range(r + 1, p):
                v = gamma_inv[r, j] - pw[r] * pw[j] / den
                avg = 0.5 * (v + v)
                gamma_inv[r, j] = avg
                gamma_inv[j, r] = avg
        # (35)-(36): gain h Gamma^-1 w
        for r in range(p):
            s = 0.0
            for j in range(p):
                s += gamma_inv[r, j] * w[j]
            pw[r] = h * s
        for r in range(2):
            innov = e_prior[r] - xi_hat[r]
            wt = 0.0
            for j in range(p):
                wt += w[j] * theta[r, j]
            u = innov + wt
            dwt = 0.0
            for j in range(p):
                d = innov * pw[j]
                theta[r, j] += d
                dwt += d * w[j]
                blk_c[bj, r, j] += h * u * w[j]
            eta_hat[r] += dwt  # the w theta_hat' term of (26)
            blk_uu[bj, r] += h * u * u
            blk_ee[bj, r] += h * e_prior[r] * e_prior[r]
        for j in range(p):
            g_prev[j] = g[row, j]
        st[7] = (e1 - st[1]) / h
        st[8] = (e2 - st[2]) / h
        st[0] = t[i]
        st[1] = e1
        st[2] = e2
        if hi < m and hist_idx[hi] == n_i:
            # element by element: an array assigned to a slice compiles numba's shape-mismatch message (its string
            # formatting), 2.2 of this kernel's 4.4 s of compiling in each fresh process
            for j in range(p):
                hist_theta[hi, 0, j] = theta[0, j]
                hist_theta[hi, 1, j] = theta[1, j]
                for q in range(p):
                    hist_gamma[hi, j, q] = gamma[j, q]
            hist_e[hi, 0] = e_prior[0]
            hist_e[hi, 1] = e_prior[1]
            hi += 1
    cursor[0] = hi
    cursor[1] = bj


@kernel
def _solve_in_place(a, b):
    """Solve a x = b (a (n, n), b (n,)) by Gaussian elimination with partial pivoting, as LAPACK's gesv does;
    ``a`` and ``b`` are overwritten (x in ``b``).

    The projection's free-set systems are principal blocks of the observer's gamma, at most 8 x 8: this compiles in
    a fraction of a second where numpy's solve (numba's LAPACK binding) took about 2 s in each fresh process.  An
    exactly singular block raises LinAlgError, as numpy's solve did."""
    n = a.shape[0]
    for j in range(n):
        pivot = j
        for i in range(j + 1, n):
            if abs(a[i, j]) > abs(a[pivot, j]):
                pivot = i
        if a[pivot, j] == 0.0:
            raise np.linalg.LinAlgError("the free set's block of gamma is singular")
        if pivot != j:
            for c in range(n):
                a[j, c], a[pivot, c] = a[pivot, c], a[j, c]
            b[j], b[pivot] = b[pivot], b[j]
        for i in range(j + 1, n):
            f = a[i, j] / a[j, j]
            for c in range(j + 1, n):
                a[i, c] -= f * a[j, c]
            b[i] -= f * b[j]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for c in range(i + 1, n):
            s -= a[i, c] * b[c]
        b[i] = s / a[i, i]


@kernel
def project_row_box(x0, gamma, lo, hi, out):
    """argmin over lo <= x <= hi of (x - x0)^T gamma (x - x0) into ``out`` (p,); gamma SPD (p, p).

    The primal active-set method for a convex quadratic with bounds (Nocedal & Wright, Alg. 16.3):
    start at the clipped point, solve the equality-constrained problem on the free set, step to the
    first blocking bound or release the bound whose multiplier has the wrong sign.  Finite and exact
    (to rounding) for the p <= 8 of the regressor; returns x0 itself when it lies inside the box.
    Returns the number of iterations (-1 if the iteration cap was hit).
    """
    p = x0.shape[0]
    inside = True
    for j in range(p):
        if x0[j] < lo[j] or x0[j] > hi[j]:
            inside = False
    if inside:
        for j in range(p):
            out[j] = x0[j]
        return 0
    # state: 0 free, -1 at lower bound, +1 at upper bound
    state = np.zeros(p, dtype=np.int64)
    x = np.empty(p)
    for j in range(p):
        if x0[j] < lo[j]:
            x[j] = lo[j]
            state[j] = -1
        elif x0[j] > hi[j]:
            x[j] = hi[j]
            state[j] = 1
        else:
            x[j] = x0[j]
    target = np.empty(p)
    for it in range(1, 20 * p + 20):
        # Equality-constrained minimiser on the free set F: gamma_FF (y_F - x0_F) = -gamma_FA (x_A - x0_A)
        nf = 0
        for j in range(p):
            if state[j] == 0:
                nf += 1
        for j in range(p):
            target[j] = x[j]
        if nf > 0:
            free = np.empty(nf, dtype=np.int64)
            c = 0
            for j in range(p):
                if state[j] == 0:
                    free[c] = j
                    c += 1
            a = np.empty((nf, nf))
            rhs = np.empty(nf)
            for r in range(nf):
                s = 0.0
                for j in range(p):
                    if state[j] != 0:
                        s -= gamma[free[r], j] * (x[j] - x0[j])
                rhs[r] = s
                for q in range(nf):
                    a[r, q] = gamma[free[r], free[q]]
            _solve_in_place(a, rhs)
            for r in range(nf):
                target[free[r]] = x0[free[r]] + rhs[r]
        # Step from x towards target, stopped by the first free variable that would leave the box.
        step = 1.0
        block = -1
        for j in range(p):
            if state[j] != 0:
                continue
            d = target[j] - x[j]
            if d < 0.0 and target[j] < lo[j]:
                frac = (lo[j] - x[j]) / d
                if frac < step:
                    step, block = frac, j
            elif d > 0.0 and target[j] > hi[j]:
                frac = (hi[j] - x[j]) / d
                if frac < step:
                    step, block = frac, j
        for j in range(p):
            if state[j] == 0:
                x[j] = x[j] + step * (target[j] - x[j])
        if block >= 0:
            if target[block] < lo[block]:
                x[block] = lo[block]
                state[block] = -1
            else:
                x[block] = hi[block]
                state[block] = 1
            continue
        # At the minimiser on this active set: release the bound with the most negative multiplier.
        worst = 0.0
        release = -1
        for j in range(p):
            if state[j] == 0:
                continue
            grad = 0.0
            for q in range(p):
                grad += gamma[j, q] * (x[q] - x0[q])
            # multiplier >= 0 means the bound holds the point: grad >= 0 at a lower, <= 0 at an upper bound
            mult = grad if state[j] == -1 else -grad
            if mult < worst:
                worst, release = mult, j
        if release < 0:
            for j in range(p):
                out[j] = min(max(x[j], lo[j]), hi[j])
            return it
        state[release] = 0
    for j in range(p):
        out[j] = min(max(x[j], lo[j]), hi[j])
    return -1


@kernel
def project_history_box(theta, gamma, lo, hi, out):
    """Project each history entry theta (m, 2, p) with its gamma (m, p, p) onto the box, into ``out``."""
    worst = 0
    for i in range(theta.shape[0]):
        for r in range(theta.shape[1]):
            it = project_row_box(theta[i, r], gamma[i], lo[r], hi[r], out[i, r])
            if it < 0:
                worst = -1
    return worst
