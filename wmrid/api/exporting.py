"""``wmrid export``: an identification result written as a model a simulator or a controller loads.

:func:`export` takes a result (a saved JSON or an :class:`~wmrid.estimators.result.IdentificationResult`) and the robot
file it was identified with, computes the physical quantities (:mod:`wmrid.model.physical`: what the log determines,
what the file gives, what stays undetermined; an unphysical result is refused) and writes, by the output's suffix:

* ``.xml``: MJCF, the multibody prototype with the identified values (:mod:`wmrid.exports.mjcf`);
* ``.urdf``: the robot's own URDF with only the base link's inertial and the wheel joints' dynamics changed, or a
  minimal URDF for a TOML robot (:mod:`wmrid.exports.urdf`);
* ``.yaml`` / ``.yml``: the reduced model for a controller; ``.py``: a dependency-free ``wheel_torques(eta, eta_dot)``
  (:mod:`wmrid.exports.controller`);
* ``.toml``: a wmrid robot file of the identified robot, which ``wmrid simulate`` reads
  (:mod:`wmrid.exports.robot_file`).

``check``: a log whose torques drive the exported multibody model over windows restarted from the logged speeds
(:func:`wmrid.sim.open_loop.drive_windows`); the fit % per wheel is reported next to the reduced model's on the same
windows (:func:`wmrid.model.predict.simulate_segments`).  The returned :class:`ExportResult` round-trips through JSON.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.model.export_result import ExportCheck, ExportResult
from wmrid.model.physical import PhysicalEstimate

#: Suffixes :func:`export` writes, and what each is.
EXPORT_FORMATS = {
    ".xml": "MJCF (MuJoCo)", ".urdf": "URDF", ".yaml": "YAML (reduced model)", ".yml": "YAML (reduced model)",
    ".py": "Python (wheel_torques)", ".toml": "wmrid robot file",
}  # fmt: skip
#: Default length (s) of the windows ``check`` restarts the models over.
CHECK_WINDOW = 2.0
#: The shortest window, in samples of the check log: over fewer, restarting from the logged speeds makes any model fit.
MIN_WINDOW_SAMPLES = 10


def check_export_output(path: str | os.PathLike[str]) -> str:
    """The output's suffix (lower case), or UsageError naming the suffixes :func:`export` writes."""
    target = os.fspath(path)
    suffix = Path(target).suffix.lower()
    if suffix not in EXPORT_FORMATS:
        raise UsageError(
            f"{option('output', target)}: give a file ending in {', '.join(EXPORT_FORMATS)} (MJCF, URDF, YAML, "
            "Python, a wmrid robot file)"
        )
    return suffix


def _result(result: Any) -> tuple[Any, dict[str, str]]:
    """(IdentificationResult, provenance) from a result or the path of a saved one."""
    from wmrid import __version__
    from wmrid.estimators.result import IdentificationResult, from_dict as result_from_dict

    provenance = {"wmrid": __version__}
    if isinstance(result, IdentificationResult):
        found = result
        provenance["result"] = "an IdentificationResult (not saved)"
    else:
        from wmrid.api.inputs import read_json_input

        source = os.fspath(result)
        data = read_json_input(source, f"result {source}", "a saved identification result")
        found = result_from_dict(data, source)
        hasher = hashlib.sha256()
        with open(source, "rb") as fh:  # read once more to name it exactly, in pieces (memory bounded)
            for piece in iter(lambda: fh.read(1 << 20), b""):
                hasher.update(piece)
        provenance["result"] = f"{source} (sha256 {hasher.hexdigest()})"
    if found.estimate is None:
        raise UsageError(f"{provenance['result']}: holds no estimate to export")
    provenance.update({
        "log": str(found.source), "method": str(found.estimate.method),
        "friction_model": found.form.friction,
    })  # fmt: skip
    return found, provenance


def _notes(est: PhysicalEstimate) -> dict[str, str]:
    out = {}
    for name, q in est.quantities.items():
        unit = "" if q.unit == "1" else f" {q.unit}"
        if q.source == "robot file":
            out[name] = f"{q.value:.6g}{unit} (robot file)"
            continue
        std = "undetermined" if not math.isfinite(q.std) else f"{q.std:.3g}"
        out[name] = f"{q.value:.6g} +/- {std}{unit} ({q.source})"
    return out


def export(
    result: Any,
    robot: Any,
    output: str | os.PathLike[str],
    *,
    check: Any = None,
    window: float = CHECK_WINDOW,
    gear_ratio: float | None = None,
    rotor_inertia: float | None = None,
    wheel_radius: float | None = None,
    options: Any = None,
    force: bool = False,
) -> ExportResult:
    """Write an identified robot as a model a simulator or a controller loads (``wmrid export``).

    The physical quantities are computed from the result and the robot file (:mod:`wmrid.model.physical`: what the
    log determines, what the file gives, what stays undetermined; an unphysical result is refused).  The output is
    written atomically, in the format its suffix names:

    * ``.xml``: MJCF, the multibody prototype with the identified values (:mod:`wmrid.exports.mjcf`);
    * ``.urdf``: the robot's own URDF with only the base link's inertial and the wheel joints' dynamics changed, or
      a minimal URDF for a TOML robot (:mod:`wmrid.exports.urdf`);
    * ``.yaml`` / ``.yml``: the reduced model for a controller; ``.py``: a dependency-free
      ``wheel_torques(eta, eta_dot)`` (:mod:`wmrid.exports.controller`);
    * ``.toml``: a wmrid robot file of the identified robot, which ``wmrid simulate`` reads
      (:mod:`wmrid.exports.robot_file`).

    Parameters
    ----------
    result
        The identification: a saved result's path, or an :class:`IdentificationResult`.
    robot
        The robot it was identified with: a robot file, a built-in name, or a URDF with ``gear_ratio``.
    output
        The file to write; its suffix names the format (above).
    check
        A log (a path, read with ``options``, or a log) whose torques drive the exported multibody model over
        windows restarted from the logged speeds (:func:`wmrid.sim.open_loop.drive_windows`); the fit % per wheel is
        reported next to the reduced model's on the same windows (:func:`wmrid.model.predict.simulate_segments`).
        None: no check.
    window
        s, the length of the check's windows, > 0.
    gear_ratio
        The gear ratio of a URDF robot (required for one).
    rotor_inertia
        kg m^2, a URDF robot's rotor inertia when it has no rotor links.
    wheel_radius
        m, overrides a URDF robot's wheel radius.
    options
        How to read ``check`` when it is a path (:class:`~wmrid.api.inputs.LogOptions`).
    force
        Overwrite an existing output (else it is kept).

    Returns
    -------
    ExportResult
        What was written, with the physical quantities, the provenance and the check's fits; it round-trips through
        JSON.

    Raises
    ------
    UsageError
        One line, for an unknown suffix, a robot file without physical parameters, an unphysical result, a result
        whose effort is not a torque.
    """
    from wmrid.api.inputs import load_robot
    from wmrid.exports.controller import controller_model
    from wmrid.model.robot import PhysicalParameters
    from wmrid.runtime.atomic import _check_target, atomic_write_bytes, atomic_write_text

    suffix = check_export_output(output)
    _check_target(Path(os.fspath(output)), force)  # before any work: an existing output, a missing folder
    if not (isinstance(window, (int, float)) and math.isfinite(window) and window > 0):
        raise UsageError(f"{option('window', window)}: give the check's window length in seconds, > 0")
    robot_obj = load_robot(robot, gear_ratio=gear_ratio, rotor_inertia=rotor_inertia, wheel_radius=wheel_radius)
    found, provenance = _result(result)
    robot_name = os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else robot_obj.name
    _same_robot(found, robot_obj, robot_name)
    _determined(found)
    said: list[str] = []
    notes_log = list(found.log_info.notes)
    if notes_log:
        provenance["log_notes"] = " ".join(notes_log)
    unit = found.log_info.effort_unit
    # the robot file's masses and geometry taken as known: its CAD set when it has one (the measured robot), else
    # its nominal set
    cad = robot_obj.cad
    use_cad = isinstance(cad, PhysicalParameters)
    geometry = cad if isinstance(cad, PhysicalParameters) else robot_obj.nominal
    provenance["robot"] = f"{robot_obj.name} ({'CAD' if use_cad else 'nominal'} set for what the log does not give)"
    cm = controller_model(found, provenance)
    simulator = suffix in (".xml", ".urdf", ".toml")
    physical = None
    if unit != "N m" or not robot_obj.physical:
        why = (
            f"the result's efforts are in {unit}, not N m: its parameters are not masses and inertias"
            if unit != "N m"
            else f"{option('robot', robot_name)} gives base parameters only, not the geometry and masses"
        )
        if simulator or check is not None:
            raise UsageError(f"{why}; only the controller formats (.yaml, .py) can hold this result")
        said.append(f"{why}: the physical quantities are left out")
    else:
        physical = _physical(found, geometry, simulator, said)
    if found.form.caster and not found.form.geometry and simulator:
        said.append(
            "the two-term caster drag (Cv, Cw) has no place in a multibody model: it is not in this file (the .yaml "
            "and .py exports keep it)"
        )
    checked = None
    if check is not None:  # before anything is written: a check that cannot run leaves no file behind
        assert physical is not None  # a check without the physical quantities is refused above
        checked = check_fit(found, physical, robot_obj, check, window=window, options=options, casters=cm.casters())
        if any(v is not None and v < 0 for _, fit in checked.fits() for v in fit.values()):
            said.append("a fit below 0 % predicts the check log worse than its mean: is it a log of this robot?")
    notes = _notes(physical) if physical is not None else {}
    prov_line = "; ".join(f"{k}: {v}" for k, v in provenance.items())
    casters = robot_obj.casters
    target = os.fspath(output)
    extra = list(said)
    if suffix == ".xml":
        from wmrid.exports.mjcf import mjcf_text
        from wmrid.model.robot import default_casters

        assert physical is not None  # a simulator's file without the physical quantities is refused above
        text = mjcf_text(physical.parameters, casters or default_casters(physical.parameters), notes, prov_line,
                         cm.casters(), extra)  # fmt: skip
        atomic_write_text(target, text, force=force)
    elif suffix == ".urdf":
        from wmrid.exports.urdf import minimal_urdf, updated_urdf

        assert physical is not None  # a simulator's file without the physical quantities is refused above
        assert isinstance(geometry, PhysicalParameters)  # so is a robot of base parameters only
        source = os.fspath(robot) if isinstance(robot, (str, os.PathLike)) else ""
        if source.lower().endswith(".urdf"):
            from wmrid.runtime.limits import ROBOT_FILE_LIMIT, read_limited

            data = read_limited(source, max(ROBOT_FILE_LIMIT, 64 << 20), f"{source}: holds more than {{size}}",
                                UsageError)  # fmt: skip
            reread = f"read it back with --gear-ratio {geometry.k_r:g}"
            if rotor_inertia is not None:
                reread += f" --rotor-inertia {rotor_inertia:g}"
            out = updated_urdf(data, source, physical.parameters, gear_ratio=geometry.k_r,
                               rotor_inertia=rotor_inertia, wheel_radius=wheel_radius, notes=notes,
                               provenance=f"{prov_line}; {reread}", said=said)  # fmt: skip
            atomic_write_bytes(target, out, force=force)
        else:
            from wmrid.model.robot import default_casters

            p = physical.parameters
            reread = f"--gear-ratio {p.k_r:g}" + (f" --rotor-inertia {p.I_r:g}" if p.m_r <= 0 < p.I_r else "")
            text = minimal_urdf(p, casters or default_casters(p), robot_obj.name, notes, prov_line, extra)
            atomic_write_text(target, text, force=force)
            kind = "a robot given as an object" if not source else "a TOML robot"
            said.append(f"{kind} has no URDF to edit: a minimal URDF was written (read it back with {reread})")
    elif suffix == ".toml":
        from wmrid.exports.robot_file import robot_file_text

        assert physical is not None  # a simulator's file without the physical quantities is refused above
        loads: list[float] = []
        if robot_obj.casters and cm.casters():
            from wmrid.sim.open_loop import settled_caster_loads

            loads = settled_caster_loads(physical.parameters, robot_obj.casters).tolist()
        text = robot_file_text(robot_obj, physical.parameters, notes, provenance, cm.casters(), loads, extra)
        atomic_write_text(target, text, force=force)
    elif suffix in (".yaml", ".yml"):
        from wmrid.exports.controller import yaml_text

        atomic_write_text(target, yaml_text(cm), force=force)
    else:
        from wmrid.exports.controller import python_text

        atomic_write_text(target, python_text(cm), force=force)
    return ExportResult(path=target, format=EXPORT_FORMATS[suffix], physical=physical, provenance=provenance,
                        check=checked, notes=tuple(said))  # fmt: skip


#: Relative difference above which the result's starting M, Vc are not the robot file's: another robot.
SAME_ROBOT = 1e-6


def _same_robot(found: Any, robot_obj: Any, name: str) -> None:
    """UsageError when the result was started from another robot's nominal set (its M and Vc differ from the file's):
    its base parameters would be turned into masses with the wrong geometry."""
    from wmrid.model import dynamics as model

    start = found.nominal or {}
    if not all(k in start for k in ("m11", "m12", "m22", "Vc")):
        return
    mine = model.base_parameters(robot_obj.nominal)  # a base set gives its theta0
    theirs = np.array([start[k] for k in ("m11", "m12", "m22", "Vc")], dtype=float)
    scale = np.maximum(np.abs(mine[:4]), 1e-12)
    worst = int(np.argmax(np.abs(theirs - mine[:4]) / scale))
    if abs(theirs[worst] - mine[worst]) / scale[worst] > SAME_ROBOT:
        label = ("m11", "m12", "m22", "Vc")[worst]
        raise UsageError(
            f"the result was identified from another robot's nominal values ({label} {theirs[worst]:.6g} there, "
            f"{mine[worst]:.6g} in {name}): export it with the robot file it was identified with"
        )


def _determined(found: Any) -> None:
    """UsageError when the log does not determine the inertia or Vc: there is no identified robot to export."""
    cov = np.asarray(found.estimate.cov, dtype=float)
    names = ("m11", "m12", "m22", "Vc")
    missing = [n for i, n in enumerate(names) if not np.isfinite(cov[i, i])]
    if missing:
        raise UsageError(
            f"the log does not determine {', '.join(missing)} (their values are the start's): there is no identified "
            "robot to export; drive as `wmrid plan` designs it and identify again"
        )


#: A negative identified friction within this many std of 0 is written as 0 in a simulator's file (with a note);
#: further below, the export is refused.
NEGATIVE_FRICTION_STD = 3.0


def _physical(found: Any, geometry: Any, simulator: bool, said: list[str]) -> PhysicalEstimate:
    from wmrid.model.physical import physical_from_base

    est = found.estimate
    base_names = found.form.base_names if len(est.theta0) == found.form.n_base else None
    meanings = {}
    if found.form.caster and found.form.geometry:
        for k in range(found.form.n_casters):
            x, y = found.form.geometry[2 + 2 * k], found.form.geometry[3 + 2 * k]
            meanings[f"D{k + 1}"] = (f"rolling drag force of the casters at (+-{abs(x):.4g}, {y:.4g}) m together "
                                     "(their drag columns are the same)")  # fmt: skip
            for sig, what in (("dv", "v'"), ("w2", "w^2"), ("vw", "v w"), ("dw", "w'")):
                meanings[f"D{k + 1}{sig}"] = f"how D{k + 1} grows with {what} (the casters' load moving)"
    physical = physical_from_base(np.asarray(est.theta0), np.asarray(est.cov), geometry, base_names, meanings)
    for name in physical.clipped:
        q = physical.quantities[name]
        text = f"identified {name} = {q.value:.3g} +/- {q.std:.2g} {q.unit} is negative"
        if simulator and math.isfinite(q.std) and q.value < -NEGATIVE_FRICTION_STD * q.std:
            raise UsageError(f"{text}, more than {NEGATIVE_FRICTION_STD:g} std below 0: a simulator cannot hold it "
                             "(the .yaml and .py exports can)")  # fmt: skip
        if simulator:
            said.append(f"{text}; written as 0 (within {NEGATIVE_FRICTION_STD:g} std of it)")
    return physical


def check_fit(
    found: Any, physical: PhysicalEstimate, robot_obj: Any, log: Any, *, window: float, options: Any = None,
    casters: list[dict[str, float]] | None = None,
) -> ExportCheck:  # fmt: skip
    """Fit % per wheel of the exported multibody model and of the reduced model, both driven by ``log``'s torques over
    windows of ``window`` s restarted from its logged speeds (module docstring)."""
    from wmrid.api.identification import _log
    from wmrid.model.predict import fit_percent, simulate_segments, unsimulated
    from wmrid.model.robot import default_casters
    from wmrid.sim.multibody_model import MultibodySettings
    from wmrid.sim.open_loop import drive_windows

    wheel_log = _log(log, options, robot_obj, whole=True)
    if wheel_log.effort_unit != "N m":
        raise UsageError(f"{option('check', wheel_log.source)}: its efforts are in {wheel_log.effort_unit}, not N m")
    t, eta, tau = np.asarray(wheel_log.t), np.asarray(wheel_log.eta), np.asarray(wheel_log.tau)
    if len(t) < 3:
        raise UsageError(f"{option('check', wheel_log.source)}: has {len(t)} samples; the check needs a log")
    step = float(np.median(np.diff(t)))
    if window < MIN_WINDOW_SAMPLES * step:
        raise UsageError(
            f"{option('window', window)}: shorter than {MIN_WINDOW_SAMPLES} samples of the check log ({step:.3g} s "
            "each), where any model fits; give a longer window"
        )
    starts = np.searchsorted(t, np.arange(t[0], t[-1], window))
    starts = np.unique(starts[starts < len(t) - 1])
    p = physical.parameters
    robot_casters = robot_obj.casters or default_casters(p)
    forces, drag = None, None
    if casters and found.form.load:
        # a drag that follows the load: the prototype's own law, resistance x the contact's normal load, with the
        # resistance that gives D_k at rest (shared by the casters of its group, as the robot-file export does)
        from wmrid.exports.robot_file import group_resistance
        from wmrid.sim.open_loop import settled_caster_loads

        drag = np.array(group_resistance(robot_casters, casters, settled_caster_loads(p, robot_casters))[0])
    elif casters:
        # the identified drag force D_k of each caster of the geometric model, applied as a constant force against
        # its contact's motion (the model's own law); a caster of the file at the same place carries it
        forces = np.zeros(len(robot_casters))
        for c in casters:
            k = min(range(len(robot_casters)), key=lambda i: math.hypot(robot_casters[i].x - c["x"],
                                                                        robot_casters[i].y - c["y"]))  # fmt: skip
            forces[k] += c["D"]
    settings = MultibodySettings(caster_resistance=0.0)  # the drag is the identified one, set above
    mj = drive_windows(p, robot_casters, t, eta, tau, starts, drag=drag, forces=forces, settings=settings)
    est = found.estimate
    form = found.form if len(est.theta0) == found.form.n_base else None
    why = unsimulated(form)
    fit_mj = fit_percent(eta, mj)
    if why:
        fit_red = np.full(2, np.nan)
    else:
        fit_red = fit_percent(eta, simulate_segments(t, tau, np.asarray(est.theta0), eta, starts, form=form))

    def clean(v: float) -> float | None:
        return float(v) if math.isfinite(v) else None

    return ExportCheck(
        log=wheel_log.source, samples=len(t), window_s=window, windows=len(starts),
        definition="fit = 100 (1 - ||eta - eta_hat|| / ||eta - mean(eta)||) per wheel, the models restarted from the "
                   "logged speeds at the start of each window and driven by the logged torques",
        multibody={"eta_r": clean(fit_mj[0]), "eta_l": clean(fit_mj[1])},
        reduced={"eta_r": clean(fit_red[0]), "eta_l": clean(fit_red[1])},
        reduced_not_simulated=why,
    )  # fmt: skip


def write_export_summary(result: ExportResult, path: str | os.PathLike[str], *, force: bool = False) -> None:
    from wmrid.runtime.atomic import write_json

    write_json(os.fspath(path), result.to_dict(), force=force)
