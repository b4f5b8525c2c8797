"""Reports as one call: :func:`report` builds what ``wmrid report`` writes (tables after the paper's Tables 2 and 3,
the comparison with nominal/CAD values and a truth, diagnostics, figures), and :func:`write_report` writes it as
HTML, Markdown or JSON by the file's suffix.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from typing import Any

from wmrid.api.identification import (
    check_rotor_inertia,
    check_validation,
    prepare,
    run_prepared,
    settings_given,
    validate as validated,
)
from wmrid.api.inputs import LogOptions, given_results, read_log
from wmrid.core.errors import LogFormatError, UsageError, WmridError, option
from wmrid.core.wheel_log import LogStream, WheelLog
from wmrid.estimators.options import MethodOptions, ObserverOptions
from wmrid.estimators.result import IdentificationResult, from_dict
from wmrid.model.robot import Robot
from wmrid.reporting.report import Report, build_report

__all__ = ["Identification", "report", "residual_frame", "write_report"]

#: Report formats by the output's suffix.
REPORT_SUFFIXES = (".html", ".htm", ".md", ".json")


def _parse_saved(source: Any) -> Any:
    """The JSON document of a saved result (a file, or standard input already read), in bounded memory."""
    from wmrid.runtime.atomic import register_input
    from wmrid.runtime.limits import memory_budget, read_limited

    if source.data is None:
        register_input(source.path)
    raw = source.data if source.data is not None else read_limited(
        source.path, memory_budget(), f"{source.name}: holds more than {{size}} (WMRID_MEMORY_BUDGET)", UsageError
    )  # fmt: skip
    try:
        return json.loads(raw)
    except RecursionError:
        raise UsageError(f"{source.name}: nested too deeply to be a saved result") from None
    except ValueError as err:
        raise UsageError(f"{source.name}: starts like JSON but is not valid JSON ({err})") from err


def _from_saved(data: Any, name: str, truth: dict[str, float] | None, figures: bool) -> Report:
    """The report of a saved result; whatever it lacks or holds malformed is named, with the file."""
    if isinstance(data, dict) and not data.get("source"):
        data["source"] = name
    saved = from_dict(data, name)  # names the file in its message, not the log it came from
    try:
        return build_report(saved, document=data, truth=truth, figures=figures)
    except WmridError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
        what = f"no {err.args[0]!r}" if isinstance(err, KeyError) and err.args else " ".join(str(err).split())
        raise LogFormatError(
            f"{name}: not a complete identify result ({what}); give a log, or the unedited output of "
            "`wmrid identify LOG --format json`"
        ) from err


def report(
    result: IdentificationResult | dict[str, Any] | str | os.PathLike[str] | WheelLog | LogStream,
    *,
    log: WheelLog | None = None,
    truth: dict[str, float] | None = None,
    figures: bool = True,
    options: LogOptions | None = None,
    robot: str | os.PathLike[str] | Robot | None = None,
    rotor_inertia: float | None = None,
    command: str | None = None,
    identification: Identification | None = None,
) -> Report:
    """The report of an identification: what ``wmrid report`` writes.

    Tables after the paper's Tables 2 and 3, the comparison with nominal/CAD values and a truth, diagnostics and
    figures.

    Parameters
    ----------
    result
        An :class:`IdentificationResult`; a saved ``identify --format json`` document (a dict, or a path to one;
        ``"-"`` standard input); or a log (a path, or a log in memory), identified here on ``robot`` as
        ``identification`` says.
    log
        The identified log in memory, for the torque residual and the figures of the signals.
    truth
        True base parameters by name (a simulator's ``truth["parameters"]``), for the error columns.
    figures
        Build the figures (:mod:`wmrid.reporting.svg`; each is rendered once, when an output needs it).
    options
        How to read a log given as a path (:class:`~wmrid.api.inputs.LogOptions`).
    robot
        The robot a log is identified on, as for :func:`identify`.  It is loaded only for a log (a saved result
        carries its nominal and CAD values).
    rotor_inertia
        kg m^2, a URDF robot's rotor inertia when it has no rotor links (a log only).
    command
        The command line that made the report, for its reproducibility block (the CLI gives it).
    identification
        How a log is identified (:class:`Identification`: the method, the options, a log to validate on, earlier
        results; None: the defaults).

    Returns
    -------
    Report
        The report; ``report.provenance`` holds wmrid's version, the time (UTC), the command, the options given, and
        each input file's size and SHA-256.  :func:`write_report` writes it.

    Raises
    ------
    UsageError
        A saved result given with a validation, a method other than the observer, or earlier results (they need a
        log), or a file that is not valid JSON.
    LogFormatError
        A saved result that is not a complete identify result.
    """
    how = identification if identification is not None else Identification()
    rep, inputs, data = _report(result, log, truth, figures, options, robot, rotor_inertia, how)
    return replace(rep, provenance=_provenance(command, inputs, data, options, robot, rotor_inertia, how))


@dataclass(frozen=True)
class Identification:
    """How :func:`report` identifies a log it is given.

    Attributes
    ----------
    method
        The method, as for :func:`wmrid.api.identification.identify`.
    observer
        The observer's options, as for :func:`wmrid.api.identification.identify`.
    fit
        The classical methods' options, as for :func:`wmrid.api.identification.identify`.
    validate
        Another log to predict (:func:`wmrid.api.identification.validate`), or None.
    given
        Earlier results to combine with, as ``identify``'s ``given``, or None.
    """

    method: str = "auto"
    observer: ObserverOptions = field(default_factory=ObserverOptions)
    fit: MethodOptions = field(default_factory=MethodOptions)
    validate: Any = None
    given: Any = None


def _report(
    result: IdentificationResult | dict[str, Any] | str | os.PathLike[str] | WheelLog | LogStream,
    log: WheelLog | None,
    truth: dict[str, float] | None,
    figures: bool,
    options: LogOptions | None,
    robot: str | os.PathLike[str] | Robot | None,
    rotor_inertia: float | None,
    how: Identification,
) -> tuple[Report, list[str], bytes | None]:
    """(report, the input paths to record, the standard input's bytes or None)."""
    if isinstance(result, IdentificationResult):
        return build_report(result, log=log, truth=truth, figures=figures), [], None
    if isinstance(result, dict):
        return _from_saved(dict(result), str(result.get("source") or "result"), truth, figures), [], None
    validate, method = how.validate, how.method
    check_rotor_inertia(rotor_inertia)  # before INPUT is opened, as identify does
    inputs: list[str] = []
    data = None
    if isinstance(result, (str, os.PathLike)):
        from wmrid.io.sources import open_source

        check_validation(result, validate, how.observer, (method,), option("input_"))
        source = open_source(os.fspath(result))
        inputs, data = [os.fspath(result)], source.data
        if source.head(64).lstrip().startswith(b"{"):
            if validate is not None or method not in ("auto", "observer") or how.given:
                raise UsageError(
                    f"{source.name}: {option('validate')}, {option('method')} and {option('given')} need a log as "
                    "INPUT, not a saved result; run `wmrid identify LOG --method ... --validate OTHER --format json` "
                    "and report its output"
                )
            return _from_saved(_parse_saved(source), source.name, truth, figures), inputs, data
    else:
        check_validation(result, validate, how.observer, (method,), option("input_"))
    # a log: the checks identify() makes, before the log is read
    prep = prepare(
        method, how.observer, how.fit, options=options, robot=robot, rotor_inertia=rotor_inertia,
        validating=validate is not None,
    )  # fmt: skip
    earlier = given_results(how.given)  # read (and refused) before the log
    if isinstance(result, (str, os.PathLike)):  # opened above: its bytes when they were read (standard input)
        wheel_log = read_log(os.fspath(result), options, robot=prep.robot, data=data)
    else:
        wheel_log = result.read() if isinstance(result, LogStream) else result
    identified = run_prepared(wheel_log, prep, given=earlier)
    if validate is not None:
        identified = validated(identified, validate, options, robot=prep.robot)
    robot_obj = prep.robot
    validation_log = validate if isinstance(validate, WheelLog) else None
    if isinstance(validate, (str, os.PathLike)) and os.fspath(validate) != "-":
        inputs.append(os.fspath(validate))
        if figures:  # its measured and predicted speeds (the identification read it, and kept only its fit)
            validation_log = read_log(os.fspath(validate), options, robot=robot_obj)
    rep = build_report(identified, log=wheel_log, truth=truth, figures=figures, validation_log=validation_log)
    return rep, inputs, data


def _provenance(
    command: str | None,
    inputs: list[str],
    data: bytes | None,
    options: LogOptions | None,
    robot: str | os.PathLike[str] | Robot | None,
    rotor_inertia: float | None,
    how: Identification,
) -> dict[str, Any]:
    """What a colleague needs to make the report again: version, time, command, options, inputs and their hashes."""
    import dataclasses

    from wmrid.io.digest import file_digests

    given: dict[str, Any] = settings_given(how.method, how.observer, how.fit)
    if how.validate is not None:
        given["validate"] = how.validate
    earlier = how.given or []
    earlier = [earlier] if not isinstance(earlier, (list, tuple)) else list(earlier)
    if earlier:  # --given: its files by path (a result passed in memory as "result"), and among the inputs hashed
        given["given"] = [os.fspath(g) if isinstance(g, (str, os.PathLike)) else "result" for g in earlier]
        inputs = [*inputs, *(os.fspath(g) for g in earlier if isinstance(g, (str, os.PathLike)))]
    if options is not None:
        defaults = LogOptions()
        given.update({f.name: getattr(options, f.name) for f in dataclasses.fields(LogOptions)
                      if getattr(options, f.name) != getattr(defaults, f.name)})  # fmt: skip
    if robot is not None:
        given["robot"] = robot if isinstance(robot, (str, os.PathLike)) else getattr(robot, "name", "?")
    if rotor_inertia is not None:
        given["rotor_inertia"] = rotor_inertia
    return provenance_block(command or "wmrid.report(...) from Python", given, file_digests(inputs, data))


def provenance_block(command: str, options: dict[str, Any], inputs: list[dict[str, Any]]) -> dict[str, Any]:
    """A report's reproducibility block: wmrid's version, the time (UTC), the command, the options given (paths as
    text) and the inputs with their sizes and SHA-256 (:func:`wmrid.io.digest.file_digests`)."""
    import datetime

    from wmrid import __version__

    return {
        "wmrid": __version__,
        "made_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "command": command,
        "options": {k: (os.fspath(v) if isinstance(v, os.PathLike) else v) for k, v in options.items()},
        "inputs": inputs,
    }


def residual_frame(rep: Report) -> Any:
    """The residuals over time as a DataFrame: with the log, every sample's torque residual (N m) plus the nearest
    recorded prediction error (rad/s) and lambda_min; from a saved result, its history only."""
    import pandas as pd

    result, log = rep.identification, rep.log
    h = None if result is None else result.history
    if h is None:
        raise UsageError(f"{option('residuals')}: this result holds no history; give the log itself")
    frame = pd.DataFrame({"t": h.t, "e_r": h.e[:, 0], "e_l": h.e[:, 1], "lambda_min": h.lambda_min})
    if log is not None and "torque" in rep.residuals:
        res = rep.residuals["torque"]["residual"]
        full = pd.DataFrame({"t": log.t - log.t[0], "tau_res_r": res[:, 0], "tau_res_l": res[:, 1]})
        frame = pd.merge_asof(full, frame, on="t", direction="nearest")
    return frame


def write_report(rep: Report, output: str | os.PathLike[str], *, force: bool = False) -> None:
    """Write a report as a self-contained HTML page, Markdown or JSON, atomically.

    Parameters
    ----------
    rep
        The report (:func:`report`).
    output
        The output's path; its suffix names the format: .html or .htm, .md, or .json.
    force
        Overwrite an existing file.

    Raises
    ------
    UsageError
        ``output`` has none of the suffixes above.
    OutputExistsError
        ``output`` exists and ``force`` is not given.
    """
    from wmrid.reporting.report import to_json_dict
    from wmrid.reporting.report_html import to_html
    from wmrid.reporting.report_markdown import to_markdown

    write_by_suffix(output, rep, to_html, to_markdown, to_json_dict, force=force)


def write_by_suffix(
    output: str | os.PathLike[str], rep: Any, html: Any, markdown: Any, data: Any, *, force: bool
) -> None:
    """Write a report atomically in the format its file's suffix names: ``html(rep)`` for .html/.htm,
    ``markdown(rep)`` for .md, ``data(rep)`` as JSON for .json."""
    from wmrid.runtime.atomic import atomic_write_text, write_json

    path = os.fspath(output)
    suffix = os.path.splitext(path)[1].lower()
    if suffix in (".html", ".htm"):
        atomic_write_text(path, html(rep), force=force)
    elif suffix == ".md":
        atomic_write_text(path, markdown(rep), force=force)
    elif suffix == ".json":
        write_json(path, data(rep), force=force)
    else:
        raise UsageError(f"{option('output', path)}: the report format comes from the suffix: .html, .md or .json")
