"""The observers a live run (:class:`wmrid.api.live.LiveRun`) feeds: their regressor forms chosen from the first
samples, each started (its start value and box), fed piece by piece, and the kernels warmed up before the first
message.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses; the observer's numba kernels load when a live run starts).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wmrid.api.identification import Prepared
from wmrid.estimators.options import ObserverOptions


def first_observers(
    t: np.ndarray, eta: np.ndarray, tau: np.ndarray, effort_unit: str, source: str, prep: Prepared,
    settings: ObserverOptions, notes: list[str],
) -> list[tuple[Any, Any]]:  # fmt: skip
    """(form, OnlineObserver) for each form shown live, the one shown first, from the first samples t (n,) s, eta
    (n, 2) rad/s, tau (n, 2) (not fed yet); what the choice means for the user is appended to ``notes``."""
    from wmrid.core.wheel_log import WheelLog
    from wmrid.estimators.observer.observe import caster_geometry
    from wmrid.estimators.observer.survey import survey
    from wmrid.model.dynamics import RegressorForm

    sv = survey([WheelLog(t=t, eta=eta, tau=tau, source=source)], source, effort_unit)
    choice = settings.form
    robot = prep.robot
    if prep.friction == "wheel+caster":
        geometry = caster_geometry(robot) if robot is not None and robot.casters else ()
        forms = [RegressorForm("general", caster=True, geometry=geometry)]
    else:
        first = sv.form()
        forms = [first] if first.kind == "paper" and choice != "general" else []
        if choice != "paper" or not forms:
            forms.append(RegressorForm("general"))
        if prep.friction == "auto":
            notes.append("friction: wheel live; the final result chooses between wheel and wheel+caster")
    if choice == "paper" and forms[0].kind != "paper":
        notes.append("--form paper: a wheel stops or reverses, so the general form is shown live")
    robot = robot if effort_unit == "N m" else None
    return [(f, _observer(f, sv, robot, settings)) for f in forms]


def _observer(form: Any, sv: Any, robot: Any, s: ObserverOptions) -> Any:
    """The OnlineObserver of ``form``, started from ``robot``'s nominal values (None: from the data, survey ``sv``)."""
    from wmrid.estimators.observer.observe import default_box
    from wmrid.estimators.observer.online import OnlineObserver
    from wmrid.estimators.observer.settings import ObserverSettings
    from wmrid.estimators.sign_speed import sign_half_window
    from wmrid.model import dynamics as model

    if robot is not None:
        start0 = np.concatenate([model.base_parameters(robot.nominal), np.zeros(form.n_base - 8)])
        theta_init = model.intermediate_parameters(start0, form)
    else:
        theta_init = sv.data_start(form)
    lo, hi = default_box(theta_init, form, s.box_width, robot is not None)
    settings = ObserverSettings(
        form=form, theta_init=theta_init, theta_min=lo, theta_max=hi, k=s.k, alpha=s.alpha,
        torque_hold=s.torque_hold, control_rate=s.control_rate,
    )  # fmt: skip
    return OnlineObserver(settings, sign_half_window=sign_half_window(sv.n, sv.duration))


def fed(observers: list[tuple[Any, Any]], t: np.ndarray, eta: np.ndarray, tau: np.ndarray) -> list[tuple[Any, Any]]:
    """``observers`` after a piece of samples: each fed it, the paper form's dropped (while another is left) once a
    wheel stops or reverses in the speed its sign columns take (the centred mean of
    :mod:`wmrid.estimators.sign_speed`, as the final identify's survey decides the form: a coarse encoder's speed that
    dips across zero while its mean does not keeps the paper form)."""
    kept = []
    for form, obs in observers:
        with np.errstate(over="ignore", invalid="ignore"):
            obs.feed(t, eta, tau)
        if form.kind == "paper" and len(observers) > 1:
            signs = np.array(form.signs, dtype=float)
            least = np.where(signs > 0, obs.sign_low, -obs.sign_high)  # each wheel's mean in its sign's direction
            if np.any(least <= 0):  # a wheel stopped or reversed: the paper form no longer holds
                continue
        kept.append((form, obs))
    return kept


def warm_up(tables: bool) -> None:
    """Load what the first estimate needs before the first message arrives: the readers' libraries and the compiled
    kernels (numba loads them from its cache on first use, about 1.5 s), run once on a few synthetic samples.
    ``tables``: the source may bring CSV rows (pandas and pyarrow's CSV; 63 MB of memory, not loaded for a recording or
    a WebSocket server, whose final identify does not need them either)."""
    import importlib

    from wmrid.core.extras import available
    from wmrid.core.wheel_log import WheelLog
    from wmrid.estimators.observer.observe import default_box
    from wmrid.estimators.observer.online import OnlineObserver, online_estimate
    from wmrid.estimators.observer.settings import ObserverSettings
    from wmrid.estimators.observer.survey import survey
    from wmrid.model.dynamics import RegressorForm

    names = ("pandas", "pyarrow.csv", "wmrid.io.table.csv_log") if tables else ()
    for name in (*names, "wmrid.io.mcap.reader", "wmrid.io.ros.joints"):
        if name != "pyarrow.csv" or available(name):  # pyarrow: the parquet extra
            importlib.import_module(name)
    t = np.arange(200) * 1e-3
    eta = np.column_stack([2.0 + np.sin(40 * t), 2.0 + np.cos(30 * t)])
    tau = np.column_stack([np.cos(40 * t), np.sin(30 * t)])
    sv = survey([WheelLog(t=t, eta=eta, tau=tau, source="warm-up")], "warm-up")
    for form in (RegressorForm("paper"), RegressorForm("general")):
        theta = sv.data_start(form)
        lo, hi = default_box(theta, form, 10.0, False)
        obs = OnlineObserver(ObserverSettings(form=form, theta_init=theta, theta_min=lo, theta_max=hi, k=10.0))
        with np.errstate(all="ignore"):
            obs.feed(t, eta, tau)
            online_estimate(obs)
