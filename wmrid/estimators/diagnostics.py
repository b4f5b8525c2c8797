"""What the log does to the answer: excitation, start-value sensitivity, physically impossible values, and the
warnings they call for (:func:`diagnose`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.estimators.findings import Diagnostics, StructuralMismatch, WeakDirection

#: A direction of the column-scaled information whose eigenvalue is below this fraction of the largest is
#: not excited at all (double precision resolves about 1e-16; real logs' weakest directions are ~1e-8).
UNEXCITED = 1e-12


#: Structural mismatch is reported when its p-value is below MISMATCH_P and the misfit exceeds
#: MISMATCH_RELEVANT of max |theta| (:mod:`wmrid.estimators.model_error` widens the std at its own level).
MISMATCH_P = 1e-3
MISMATCH_RELEVANT = 1e-5

#: A base parameter whose standard error exceeds this fraction of its magnitude is called poorly determined.
POORLY_DETERMINED = 0.1


#: A base parameter is not determined by the log when the start value sets it (start_sensitivity) more
#: than the data's standard error and more than this fraction of its value.
START_RELEVANT = 1e-4


#: Two base parameters whose estimates correlate beyond this are called not separable.
NOT_SEPARABLE = 0.98


def derived_poorly_determined(parameters: dict[str, tuple[float, float]], base_names: tuple[str, ...]) -> list[str]:
    """The reported parameters not in ``base_names`` (M11, M12, M22, computed from m11, m12, m22) whose standard
    error exceeds POORLY_DETERMINED of their magnitude, as for the base parameters: M = m^-1 inherits the
    uncertainty of every m entry, so M12 can be poorly determined where m12 alone is not flagged, or the reverse.
    An M computed from an undetermined m has an infinite std (undetermined itself) and is not listed here."""
    out = []
    for name, (value, std) in parameters.items():
        if name in base_names or not math.isfinite(std):
            continue
        if std > POORLY_DETERMINED * abs(value):
            out.append(name)
    return out


def poorly_text(name: str, pair: tuple[float, float], unit: str, method: str | None = None, logs: int = 1) -> str:
    """The warning for a poorly determined parameter; ``logs`` > 1: a combination of that many logs' results."""
    value, std = pair
    by = f" ({method})" if method else ""
    what = "this log" if logs <= 1 else "these logs"
    return f"{name} is poorly determined by {what}{by}: {value:.6g} +/- {std:.2g} {unit}"


def impossible_parameters(parameters: dict[str, tuple[float, float]]) -> set[str]:
    """The base parameters that :func:`physics_warnings` warns of: m11, m12, m22 (and the inertia matrix M11, M12,
    M22 computed from them) when [m11 m12; m12 m22] is not positive definite, a friction negative beyond 3 standard
    errors; a caster's drag likewise."""
    out = set()
    if all(n in parameters for n in ("m11", "m12", "m22")):
        m11, m12, m22 = (parameters[n][0] for n in ("m11", "m12", "m22"))
        if m11 <= 0 or m22 <= 0 or m11 * m22 - m12 * m12 <= 0:
            out |= {n for n in ("m11", "m12", "m22", "M11", "M12", "M22") if n in parameters}
    for name in (*FRICTION_NAMES, *(n for n in parameters if is_drag(n))):
        if name in parameters:
            value, std = parameters[name]
            if value < 0 and math.isfinite(std) and value < -3 * std:
                out.add(name)
    return out


def every_std_in_doubt(diagnostics: Diagnostics) -> bool:
    """Whether the log's misfit (the prediction misfit applied) or its units (the units check's doubt) put every std
    in doubt."""
    units = diagnostics.units
    return bool(diagnostics.prediction_misfit.applied) or bool(units is not None and units.doubt)


def flagged_names(parameters: dict[str, tuple[float, float]], diagnostics: Diagnostics) -> tuple[str, ...]:
    """The parameters whose std is not to be trusted (:mod:`wmrid.estimators.verdict`): a std not defined, an
    impossible value, or every one when the log's misfit or units put every std in doubt; in the parameters' order."""
    out = {n for n, (_, std) in parameters.items() if not math.isfinite(std)}
    out |= impossible_parameters(parameters)
    if every_std_in_doubt(diagnostics):
        out |= set(parameters)
    return tuple(n for n in parameters if n in out)


#: The wheels' friction; every one resists motion, so none is negative.
FRICTION_NAMES = ("Fv1", "Fv2", "Fd1", "Fd2")


def is_drag(name: str) -> bool:
    """Whether ``name`` is a caster-drag parameter (Cv, Cw of the two-term model, D1, D2, ... of the geometric one);
    a caster's drag resists motion, so none is negative."""
    return name in ("Cv", "Cw") or (name.startswith("D") and name[1:].isdigit())


def physics_warnings(parameters: dict[str, tuple[float, float]]) -> list[str]:
    """Warnings for base parameters that no physical robot has (:func:`impossible_parameters`): M not positive
    definite, negative friction (each beyond 3 standard errors, so that noise alone does not trigger it)."""
    impossible = impossible_parameters(parameters)
    out = []
    if "m11" in impossible:
        m11, m12, m22 = (parameters[n][0] for n in ("m11", "m12", "m22"))
        out.append(
            f"the identified inverse inertia [m11 m12; m12 m22] = [{m11:.4g} {m12:.4g}; {m12:.4g} {m22:.4g}] is not "
            "positive definite, which no robot has: the log departs from the model or does not excite it"
        )
    for name in parameters:
        if name in impossible and (name in FRICTION_NAMES or is_drag(name)):
            value, std = parameters[name]
            what = "friction" if name in FRICTION_NAMES else "a caster's drag"
            out.append(f"{name} = {value:.4g} is negative beyond 3 std ({std:.2g}): {what} cannot push; check signs")
    return out


#: Most sub-steps --control-rate may split one log step into (a 1 kHz controller under a 0.1 Hz log).
MAX_SUBSTEPS = 10_000


def control_rate_check(control_rate: float | None, sv: Any, source: str) -> list[str]:
    """Refuse a control rate that splits a step into absurdly many sub-steps; warn when it changes nothing."""
    if control_rate is None or not (math.isfinite(control_rate) and control_rate > 0):
        return []  # None, or refused by ObserverSettings with its own message
    most = round(sv.max_step * control_rate)
    if most > MAX_SUBSTEPS:
        raise UsageError(
            f"{source}: {option('control_rate')} {control_rate:g} Hz splits the longest step ({sv.max_step:.3g} s) "
            "into "
            f"{most:,} held sub-steps (at most {MAX_SUBSTEPS:,}); give the controller's rate in Hz"
        )
    rate = 1.0 / sv.median_step if sv.median_step > 0 else math.inf
    if control_rate < 1.5 * rate:
        return [
            f"--control-rate {control_rate:g} Hz is not faster than the log ({rate:.6g} Hz): each step keeps one "
            "held effort, as without the option"
        ]
    return []


def torque_unexcited(gamma: np.ndarray, alpha: float) -> bool:
    """True when a direction the log does not excite at all involves the torque columns.

    Then the inverse inertia m (the coefficients of the torques) is not determined, and every other base
    parameter, read through M = m^-1, is meaningless: e.g. constant torques alongside the constant
    Coulomb column, or a log whose signals do not vary at all.
    """
    p = gamma.shape[0]
    info = gamma - alpha * np.eye(p)
    scale = np.sqrt(np.clip(np.diag(info), 0.0, None))
    if scale[0] == 0 or scale[1] == 0:
        return True
    safe = np.where(scale > 0, scale, 1.0)
    evals, evecs = np.linalg.eigh(info / np.outer(safe, safe))
    null = evals < UNEXCITED * max(float(evals[-1]), 1e-300)
    return bool(np.any(np.abs(evecs[:2, null]) > 0.1))


def unexcited_parameters(gamma: np.ndarray, alpha: float, theta_u: np.ndarray, fit) -> list[int]:
    """Base parameters that move along regressor directions the log does not excite at all.

    Directions of the column-scaled data information Gamma - alpha I whose eigenvalue is below
    UNEXCITED of the largest carry no information (columns that are constant together, e.g. a constant
    torque and the Coulomb column).  Moving theta along such a direction by the size of theta itself
    changes theta0 through the minimum-distance gain; a parameter that changes by more than
    1e-6 of its value is not determined by the log.
    """
    p = gamma.shape[0]
    info = gamma - alpha * np.eye(p)
    scale = np.sqrt(np.clip(np.diag(info), 0.0, None))
    safe = np.where(scale > 0, scale, 1.0)
    evals, evecs = np.linalg.eigh(info / np.outer(safe, safe))
    top = max(float(evals[-1]), 1e-300)
    out: set[int] = set()
    for idx in np.flatnonzero(evals < UNEXCITED * top):
        u = evecs[:, idx] / safe
        u = u / max(np.linalg.norm(u), 1e-300)
        for row in range(2):
            step = np.zeros((2, p))
            step[row] = u * max(np.linalg.norm(theta_u[row]), 1e-300)
            moved = np.abs(fit.gain @ step.ravel())
            out |= {j for j in range(len(fit.theta0)) if moved[j] > 1e-6 * max(abs(fit.theta0[j]), 1e-300)}
    return sorted(out)


def start_sensitivity(
    gamma: np.ndarray,
    gamma_inv: np.ndarray,
    alpha: float,
    theta_init: np.ndarray,
    theta_u: np.ndarray,
    gain: np.ndarray,
) -> np.ndarray:
    """How much the start value sets each base parameter, (8,) in its units.

    The final estimate is exactly Gamma^-1 (alpha theta_init + data) (see wmrid.estimators.observer.step), so its
    sensitivity to the start is alpha Gamma^-1: about 0 along directions the log excites, the identity
    along directions it does not (where Gamma's data part is 0 and the estimate IS the start).  A start
    wrong by 100 % of max(|theta_init|, |theta_hat|) in each entry, independently, then moves theta0 by
    the returned standard deviation (propagated with the minimum-distance gain (8, 2p)).
    """
    sens_theta = alpha * gamma_inv  # (p, p)
    if not np.all(np.isfinite(sens_theta)):
        return np.full(gain.shape[0], np.inf)
    plausible = np.maximum(np.abs(theta_init), np.abs(theta_u))  # (2, p)
    per_row = [sens_theta * plausible[i][None, :] for i in range(2)]  # (p, p) each: d theta_i / d start_i
    big = np.zeros((2 * gamma.shape[0], 2 * gamma.shape[0]))
    p = gamma.shape[0]
    big[:p, :p] = per_row[0]
    big[p:, p:] = per_row[1]
    effect = gain @ big  # (8, 2p)
    return np.sqrt(np.sum(effect**2, axis=1))


def diagnose(
    gamma, alpha, form, fit, parameters, theta_cov, sens, undetermined, lo, hi, units, theta, inflation
) -> tuple[Diagnostics, list[str]]:
    """Excitation and consistency diagnostics, and the warnings they call for.

    Warnings follow from what the log does to the *answer*: columns it never excites, parameters it does not
    determine, estimates held on the box, the structural mismatch.  The warnings that quote a parameter's std
    (poorly determined, with the partners it cannot be told apart from) are made from the final std, after every
    term that widens it, by :func:`wmrid.estimators.verdict.settle`.  Eigen-directions of the column-scaled
    information matrix are reported as diagnostics (they say which regressor columns the log does not separate).
    """
    warnings: list[str] = []
    p = form.n_columns
    names0 = form.base_names
    info = gamma - alpha * np.eye(p)
    scale = np.sqrt(np.clip(np.diag(info), 0, None))
    safe = np.where(scale > 0, scale, 1.0)
    evals, evecs = np.linalg.eigh(info / np.outer(safe, safe))
    lam = np.linalg.eigvalsh(gamma)
    cond = float(evals[-1] / evals[0]) if evals[0] > 0 else math.inf
    columns = form.column_names
    weakest = []
    for idx in range(min(2, p)):
        vec = evecs[:, idx]
        involved = tuple(columns[j] for j in np.argsort(-np.abs(vec)) if abs(vec[j]) > 0.3)
        relative = float(evals[idx] / evals[-1]) if evals[-1] > 0 else 0.0
        weakest.append(WeakDirection(relative_eigenvalue=relative, columns=involved))
    dead = [columns[j] for j in range(p) if scale[j] == 0]
    if dead:
        warnings.append(
            f"the log never excites regressor column(s) {', '.join(dead)}: their parameters stay at the start value"
        )
    at_bound = [
        n
        for n, v, a, b in zip(form.theta_names(), theta.ravel(), lo.ravel(), hi.ravel(), strict=True)
        if v <= a or v >= b
    ]
    if at_bound:
        warnings.append(
            f"the estimator's internal parameters {', '.join(at_bound)} stopped at the edge of the range it allows "
            "them (the box: the signs physics requires, and with a robot file a wide box around its nominal values; "
            "--box-width): the log pulls them beyond it"
        )
    if undetermined:
        names = ", ".join(names0[j] for j in undetermined)
        warnings.insert(
            0,
            f"this log does not determine {names}: the start value, not the data, sets them (alpha = {alpha:g}), "
            "so their std is null; record a longer log that varies speeds and turning more, or lower --alpha",
        )
    rel_mismatch = inflation["relative_misfit"]
    # A significant misfit (p < 1e-3) is reported unless it is below 1e-5 of max |theta|: the
    # discretisation error of a noise-free log (about 1e-7) is significant but irrelevant.
    if fit.dof > 0 and fit.p_value < MISMATCH_P and rel_mismatch > MISMATCH_RELEVANT:
        scale = inflation["scale"]
        warnings.append(
            f"the estimator's internal parameters do not fit one set of base parameters, as the model says they must "
            f"(their misfit is {100 * rel_mismatch:.2g} % of the largest of them, beyond chance: p = "
            f"{fit.p_value:.2g}; diagnostics.structural_mismatch): the log departs from the model (slip, caster "
            f"drag, other friction, a wrong sign or unit, or the wrong --torque-hold); every std is scaled by "
            f"{scale:.3g} to cover it, and the estimates are only as good as the model"
        )
    diagnostics = Diagnostics(
        lambda_min_gamma=float(lam[0]), lambda_max_gamma=float(lam[-1]), condition_number_scaled=cond,
        weakest_directions=tuple(weakest), undetermined=tuple(names0[j] for j in undetermined),
        at_box_boundary=tuple(at_bound),
        start_sensitivity={name: float(v) for name, v in zip(names0, sens, strict=True)},
        structural_mismatch=StructuralMismatch(
            statistic=fit.chi2, dof=fit.dof, p_value=fit.p_value, relative_misfit=rel_mismatch,
            meaning="Hotelling T2 of the misfit of theta to the model's form (Eqs. 23-24) on dof directions; "
            "small p_value = theta not of the model's form",
        ),
    )  # fmt: skip
    return diagnostics, warnings


#: ``--friction auto`` takes the caster model when a Wald test puts its drag parameters off zero at this level.
AUTO_P = 1e-3


AUTO_NO_REVERSAL = (
    "neither wheel ever stops or reverses, so a caster's drag cannot be told from the wheels' Coulomb friction"
)


def caster_drag_test(result: Any, names: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Wald test of the caster-drag parameters of a ``wheel+caster`` result against zero (``names``: these of its
    parameters instead, e.g. the load terms of ``wheel+caster+load``).

    W = d^T C^-1 d over the q drag parameters d with their reported (widened) covariance C, a jackknife estimate
    on B degrees of freedom, so Hotelling's (B - q + 1) W / (B q) ~ F(q, B - q + 1) (chi-square on q when B is
    unknown).  Returns {"statistic", "dof", "p_value", "text", "negative": the drag parameters that push (every one
    when none is positive; see DRAG_SIGN_Z)}."""
    from scipy.special import chdtrc, fdtrc  # scipy.special (~0.15 s): only the caster-drag test

    names = tuple(result.form.base_names[8:] if names is None else names)
    idx = [result.form.base_names.index(n) for n in names]
    values = np.array([result.parameters[n][0] for n in names])
    cov = np.asarray(result.theta0_cov)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov)):
        return {"statistic": 0.0, "dof": len(names), "p_value": 1.0, "text": "not determined by this log"}
    stat = float(values @ np.linalg.pinv(cov, hermitian=True) @ values)
    units = result.units
    # values only: their std is the table's, which later terms may widen (wmrid.estimators.verdict)
    text = ", ".join(f"{n} = {v:.4g} {units[n]}" for n, v in zip(names, values, strict=True))
    q = len(names)
    uncertainty = result.diagnostics.uncertainty
    big_b = None if uncertainty is None else uncertainty.dof
    if big_b and big_b - q + 1 > 0:
        p_value = float(fdtrc(q, big_b - q + 1, (big_b - q + 1) * stat / (big_b * q)))
    else:
        p_value = float(chdtrc(q, stat))
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    pushing = [n for n, v, s in zip(names, values, std, strict=True) if v < -DRAG_SIGN_Z * s]
    if not np.any(values > 0):
        pushing = list(names)
    return {"statistic": stat, "dof": q, "p_value": p_value, "text": text, "negative": pushing}


#: A caster model whose drag is negative (no drag positive, or one below -DRAG_SIGN_Z of its std) is not taken by
#: ``--friction auto``: a drag pushes no robot, so what the test found off zero is something else (a sign, a unit,
#: an effect neither model has).
DRAG_SIGN_Z = 2.0
