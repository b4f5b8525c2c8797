"""The observer's settings (:class:`ObserverSettings`), validated once: no compiled code here, so that a result's types
(:mod:`wmrid.estimators.result`) load without numba (``wmrid inspect``, a saved result read back)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wmrid.core.choices import TorqueHold, values
from wmrid.core.errors import UsageError, option
from wmrid.estimators.options import check_gains
from wmrid.model.dynamics import RegressorForm


@dataclass(frozen=True)
class ObserverSettings:
    """Settings of the estimator, validated once.

    k : 1/s, filter and predictor gain (> 0).  alpha : initial Gamma = alpha I (> 0), the weight of the
    start value.  theta_init, theta_min, theta_max : (2, p) intermediate parameters (units of the
    regressor columns: see :class:`wmrid.model.dynamics.RegressorForm`).  torque_hold : "zoh" or "foh", how the
    torque varies between samples.  control_rate : Hz, the rate at which a digital controller updated the
    held (zoh) effort when the log is slower: each step is then round(h f) sub-steps whose unlogged values
    are interpolated linearly between the logged ones (None: the log has every value the controller applied).
    """

    form: RegressorForm
    theta_init: np.ndarray
    theta_min: np.ndarray
    theta_max: np.ndarray
    k: float = 1.0
    alpha: float = 1e-10
    torque_hold: str = "zoh"
    control_rate: float | None = None

    @property
    def hold_code(self) -> float:
        """The compiled kernel's ``hold``: -1 foh, 0 zoh, f > 0 zoh at control rate f Hz."""
        if self.torque_hold == "foh":
            return -1.0
        return float(self.control_rate or 0.0)

    def __post_init__(self) -> None:
        p = self.form.n_columns
        if self.torque_hold not in values(TorqueHold):
            raise UsageError(f"{option('torque_hold')} must be zoh or foh, got {self.torque_hold!r}")
        check_gains(self.k, self.alpha, self.control_rate)
        if self.control_rate is not None and self.torque_hold != "zoh":
            raise UsageError(
                f"{option('control_rate')} describes a held (zoh) effort; it cannot go with "
                f"{option('torque_hold', 'foh')}"
            )
        for name in ("theta_init", "theta_min", "theta_max"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != (2, p):
                raise UsageError(f"{name} must have shape (2, {p}) for the {self.form.kind} form, got {arr.shape}")
            if not np.all(np.isfinite(arr)) and name == "theta_init":
                raise UsageError(f"{name} must be finite")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if np.any(self.theta_min > self.theta_max):
            raise UsageError("the parameter box is empty: some theta_min > theta_max")
        if np.any(self.theta_init < self.theta_min) or np.any(self.theta_init > self.theta_max):
            raise UsageError("the start value theta_init lies outside the box [theta_min, theta_max]")
