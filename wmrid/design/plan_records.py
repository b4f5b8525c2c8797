"""The parts of a :class:`wmrid.design.plan.Plan`, typed: what it predicts, how close it comes to each limit, what the
baselines would give, what makes its parameters separable, what it assumes, and its reference sampled.

Each JSON part is a frozen :class:`~wmrid.core.json_record.JsonRecord`: ``to_dict`` writes the object a plan's JSON
holds under its key (the keys in the order given here; None: the key is absent, except the fields that are always
written), ``from_dict`` reads one back (a plan an older wmrid wrote lacks some keys; keys a record does not know are
kept in ``other``).  A figure the JSON holds as ``null`` (an infinite or undefined one: a baseline that cannot
determine a parameter) reads as None.  Units are SI; a share is a fraction (0.02 = 2 %).

* :class:`Criterion`: what the plan minimises and the value it reaches (``criterion``);
* :class:`PredictedStd`: one base parameter's predicted std (``predicted``, name -> record);
* :class:`LimitUse`: one limit and the plan's peak against it (``limits_used``, name -> record);
* :class:`BaselineForecast`: what a baseline drive would give (``baselines``, name -> record);
* :class:`Separability` (+ :class:`WheelSpread`): what lets the log tell the parameters apart (``margins``);
* :class:`PlanSettings`: how the plan was made (``settings``);
* :class:`GivenResults` (+ :class:`GivenResult`): the logs already identified whose information was added
  (``given``);
* :class:`ReferenceSamples`: the plan's reference and predicted pose on a time grid (not JSON: what
  :meth:`wmrid.design.plan.Plan.samples` returns and the reference files hold).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.json_record import JsonRecord, each, kept, names, nested, other_keys


@dataclass(frozen=True, kw_only=True)
class Criterion(JsonRecord):
    """What the plan minimises: ``name`` ("worst", "d" or "a"), ``text`` (the name as said to a user), ``value`` (a
    share: the largest relative std, their geometric mean or their rms) and ``worst`` (the base parameter with the
    largest predicted relative std of those the criterion counts)."""

    name: str | None = None
    text: str | None = None
    value: float | None = None
    worst: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class PredictedStd(JsonRecord):
    """One base parameter's predicted precision, in the parameter's unit: its ``nominal`` value, the ``scale`` its
    relative std is taken against and where that comes from (``scale_from``: "nominal value", or "floor" when the
    nominal value is 0 or small), the predicted ``std`` and ``relative`` (std / scale, a share); ``counted``: whether
    the criterion counts it (False: a nuisance parameter, the casters' load terms; None: a plan written before it
    was said, where every parameter counts)."""

    nominal: float | None = None
    scale: float | None = None
    scale_from: str | None = None
    std: float | None = None
    relative: float | None = None
    counted: bool | None = None
    other: dict[str, Any] = other_keys()

    @property
    def in_criterion(self) -> bool:
        """Whether the criterion counts this parameter (``counted``, True when not said)."""
        return self.counted is not False


@dataclass(frozen=True, kw_only=True)
class LimitUse(JsonRecord):
    """One limit of :data:`wmrid.design.limits.LIMIT_NAMES` and the plan's use of it, in ``unit``: the ``limit``
    (None: not limited), the ``bound`` the plan was designed to (the limit less the margin; None likewise), the
    plan's ``peak`` and its ``share`` of the limit (peak / limit; None without a limit)."""

    limit: float | None = kept()
    bound: float | None = kept()
    peak: float | None = None
    share: float | None = kept()
    unit: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class DriveForecast(JsonRecord):
    """What a baseline drive of the plan's duration would give, slowed down uniformly (speeds times ``slowed_by``
    <= 1) until it keeps the limits: the criterion's ``value`` (a share; None: infinite, the drive determines not
    every parameter), each base parameter's ``relative`` std (name -> share, None where infinite), the ``worst``
    parameter, the ``peaks`` of its motion (limit name -> value in the limit's unit), its ``value`` over the plan's
    (``improvement``: how many times better the plan is) and the ``friction`` model identify would fit to its log."""

    value: float | None = None
    relative: dict[str, float | None] | None = None
    worst: str | None = None
    slowed_by: float | None = None
    peaks: dict[str, float] | None = None
    improvement: float | None = None
    friction: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class OpenFloorForecast(DriveForecast):
    """A baseline slowed down for every limit but the area (an open floor), and whether it then ``leaves_area``."""

    leaves_area: bool | None = None


@dataclass(frozen=True, kw_only=True)
class BaselineForecast(DriveForecast):
    """A baseline within every limit, the area included (the comparison a plan makes), and the same drive on an open
    floor (``area_ignored``)."""

    area_ignored: OpenFloorForecast | None = nested(OpenFloorForecast)


@dataclass(frozen=True, kw_only=True)
class WheelSpread(JsonRecord):
    """How one wheel turns over the drive: the share of the time it turns forward (``forward_share``) and backward
    (``backward_share``) faster than the separability threshold, the 10th, 50th and 90th percentiles of its speed
    magnitude while doing so (``speed_percentiles``, (3,) rad/s), and the share of the time between the ramps it
    spends near standstill (``near_zero_share``)."""

    forward_share: float | None = None
    backward_share: float | None = None
    speed_percentiles: tuple[float, ...] | None = names()
    near_zero_share: float | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class Separability(JsonRecord):
    """What lets the log tell the parameters apart (:func:`wmrid.design.plan.separability`): the wheel speed above
    which a wheel counts as turning (``threshold``, rad/s), the share of the time each direction must get
    (``direction_share_min``) and the largest correlation of v and w the search allows (``corr_max``); each wheel's
    :class:`WheelSpread` (``right``, ``left``); the correlation of v and w (``corr_v_w``) and of |v| and |w|
    (``corr_abs_v_abs_w``)."""

    threshold: float | None = None
    direction_share_min: float | None = None
    corr_max: float | None = None
    right: WheelSpread | None = nested(WheelSpread)
    left: WheelSpread | None = nested(WheelSpread)
    corr_v_w: float | None = None
    corr_abs_v_abs_w: float | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class PlanSettings(JsonRecord):
    """How a plan was made: its ``duration`` (s), base ``period`` (s), ``harmonics`` per channel and ``ramp`` (s,
    from and back to rest); the ``rate`` of the written reference (Hz); the search's ``seed``; the ``criterion``'s
    name; the ``friction`` model the prediction is for and the casters' geometry (``caster_geometry``: r, b, x_1,
    y_1, ... m; empty without; None: a plan written before it was said); the observer's gain ``k`` (1/s); the
    ``target_std`` of ``--duration auto`` (a share; None: a duration was given); the grids of the search
    (``search_grid``) and of the prediction (``prediction_grid``), Hz; the search's ``starts`` and ``evaluations``;
    the ``seconds`` it took; the base parameters' names (``parameter_names``); where the noise assumed comes from
    (``noise_source``: "default", "given", ... ; None when the plan was made below :func:`wmrid.plan`)."""

    duration: float | None = None
    period: float | None = None
    harmonics: int | None = None
    ramp: float | None = None
    rate: float | None = None
    seed: int | None = None
    criterion: str | None = None
    friction: str | None = None
    caster_geometry: tuple[float, ...] | None = names()
    k: float | None = None
    target_std: float | None = kept()
    search_grid: float | None = None
    prediction_grid: float | None = None
    starts: int | None = None
    evaluations: int | None = None
    seconds: float | None = None
    parameter_names: tuple[str, ...] | None = names()
    noise_source: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class GivenResult(JsonRecord):
    """A saved result whose information a plan adds: the file it was read from (``source``), the ``log`` it was
    identified from (None: not said), its ``method`` and the base ``parameters`` it determines that the plan uses."""

    source: str | None = None
    log: str | None = kept()
    method: str | None = kept()
    parameters: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class GivenResults(JsonRecord):
    """The logs already identified whose information a plan adds (``wmrid plan --given``): one :class:`GivenResult`
    each (``results``)."""

    results: tuple[GivenResult, ...] | None = each(GivenResult)
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True)
class ReferenceSamples:
    """A plan's reference on a time grid of n samples, each a (n,) float array: ``t`` (s), ``v`` (m/s), ``omega``
    (rad/s), the wheel-speed set-points ``eta_r``, ``eta_l`` (rad/s, nominal r and b), and the predicted pose ``x``,
    ``y`` (m), ``phi`` (rad)."""

    t: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    eta_r: np.ndarray
    eta_l: np.ndarray
    x: np.ndarray
    y: np.ndarray
    phi: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        """name -> (n,) array, in the order the reference files hold them (t, v, omega, eta_r, eta_l, x, y, phi)."""
        return {"t": self.t, "v": self.v, "omega": self.omega, "eta_r": self.eta_r, "eta_l": self.eta_l,
                "x": self.x, "y": self.y, "phi": self.phi}  # fmt: skip
