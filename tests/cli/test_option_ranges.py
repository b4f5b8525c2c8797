"""Every numeric option's help states the values it takes, and the code takes exactly those: a test that walks the
Typer application.

Each numeric option of every command must say its range in its help, as ``> 0``, ``>= 0`` or ``in (a, b]`` (any
brackets; ``inf`` for an unbounded end that is allowed).  The option is then given, on the command line in this
process, values just outside each end (refused: exit 2 and the option named in the message), at each end (refused or
taken as the bracket says), inside (taken), NaN and infinity (refused unless the range includes inf).  "Taken" means
the run does not fail naming the option; the log and model paths do not exist, so a run stops there, before any
work: the numbers are checked before anything is read.  A few options only mean something beside another
(:data:`CONTEXT`: a URDF robot, the multibody engine, a payload), given with them.
"""

from __future__ import annotations

import math
import re
import typing
from pathlib import Path

import pytest
from locations import ROOT_DIR

from tests.cliutil import text, wmrid
from wmrid.cli.app import command

ROOT = ROOT_DIR
MISSING_LOG = "/nonexistent/wmrid-test/log.csv"
INTERVAL = re.compile(r"in ([(\[])\s*(-?inf|-?[0-9][0-9.e+-]*)\s*,\s*(-?inf|-?[0-9][0-9.e+-]*)\s*([)\]])")
BOUND = re.compile(r"(?<![\w-])(>=|>)\s*(-?[0-9][0-9.e+-]*)")


def _urdf_without_rotors(folder: Path) -> Path:
    """The test URDF with its rotor joints fixed (then --rotor-inertia gives I_r)."""
    text_ = (ROOT / "tests" / "data" / "paper_robot.urdf").read_text()
    path = folder / "no_rotors.urdf"
    path.write_text(text_.replace('rotor_joint" type="continuous"', 'rotor_joint" type="fixed"'))
    return path


def base_args(name: str, tmp: Path) -> list[str]:
    """Arguments that make a command stop at its first file, after the numbers are checked."""
    if name == "simulate":
        return ["-o", str(tmp / "sim.csv"), "--force", "--duration", "0.01", "--rate", "1000"]
    if name == "monitor":
        return [MISSING_LOG, "--model", "/nonexistent/wmrid-test/model.json"]
    if name == "fleet":
        return [MISSING_LOG, "-o", str(tmp / "fleet.parquet")]
    if name == "plan":
        return ["--robot", "/nonexistent/wmrid-test/robot.toml"]
    if name == "export":
        return ["/nonexistent/wmrid-test/run.json", "-o", str(tmp / "model.yaml"), "--robot", "paper"]
    return [MISSING_LOG]


#: (command, option) -> the arguments that give the option its meaning.
CONTEXT = {
    ("identify", "--rotor-inertia"): ["--robot", "{urdf}", "--gear-ratio", "30"],
    ("report", "--rotor-inertia"): ["--robot", "{urdf}", "--gear-ratio", "30"],
    ("compare", "--rotor-inertia"): ["--robot", "{urdf}", "--gear-ratio", "30"],
    ("identify", "--forgetting"): ["--method", "rls"],
    ("report", "--forgetting"): ["--method", "rls"],
    ("compare", "--control-rate"): ["--methods", "observer,idim"],
    ("simulate", "--rate"): ["--duration", "2"],
    ("simulate", "--payload-inertia"): ["--payload", "10"],
    ("simulate", "--gear-ratio"): ["--robot", "{urdf}"],
    ("simulate", "--rotor-inertia"): ["--robot", "{urdf}", "--gear-ratio", "30"],
    ("simulate", "--floor-friction"): ["--engine", "mujoco"],
    ("simulate", "--caster-resistance"): ["--engine", "mujoco"],
    ("simulate", "--torque-limit"): ["--engine", "mujoco"],
    ("export", "--gear-ratio"): ["--robot", "{urdf}"],
    ("export", "--rotor-inertia"): ["--robot", "{urdf}", "--gear-ratio", "30"],
    ("export", "--wheel-radius"): ["--robot", "{urdf}", "--gear-ratio", "30"],
}


def _is_numeric(param) -> tuple[bool, bool]:
    """(numeric, integer) for a Typer option."""
    annotation = param.type_descriptor.annotation
    kinds = typing.get_args(annotation) or (annotation,)
    return (int in kinds or float in kinds), (int in kinds and float not in kinds)


def numeric_options() -> list[tuple[str, str, str, bool]]:
    """(command, flag, help, integer) of every visible numeric option."""
    out = []
    for name, cmd in command().commands.items():
        for param in cmd.params:
            numeric, integer = _is_numeric(param) if param.param_type_name == "option" else (False, False)
            if numeric and not param.hidden:
                out.append((name, param.opts[0], param.help or "", integer))
    return out


def stated_range(help_text: str) -> tuple[float, bool, float, bool]:
    """(low, low included, high, high included) from the help text; the test fails if it states none."""
    flat = " ".join(help_text.split())
    m = INTERVAL.search(flat)
    if m:
        lo, hi = float(m.group(2)), float(m.group(3))
        return lo, m.group(1) == "[", hi, m.group(4) == "]"
    m = BOUND.search(flat)
    if m:
        return float(m.group(2)), m.group(1) == ">=", math.inf, False
    raise AssertionError(f"the help states no range: {help_text!r}")


def probes(lo: float, lo_in: bool, hi: float, hi_in: bool, integer: bool) -> list[tuple[str, bool]]:
    """(value as typed, taken?) around and inside the range."""

    def step(x: float) -> float:
        return 1.0 if integer else max(abs(x) * 0.01, 0.01)

    def typed(x: float) -> str:
        return str(int(x)) if integer and math.isfinite(x) else repr(float(x))

    out = []
    if math.isfinite(lo):
        out += [(typed(lo - step(lo)), False), (typed(lo), lo_in)]
    if math.isfinite(hi):
        out += [(typed(hi + step(hi)), False), (typed(hi), hi_in)]
        inside = (lo + hi) / 2 if math.isfinite(lo) else hi - 1
    else:
        inside = lo + 1 if math.isfinite(lo) else 0.0
    out.append((typed(round(inside) if integer else inside), True))
    if not integer:
        out += [("nan", False), ("inf", math.isinf(hi) and hi_in), ("-inf", math.isinf(lo) and lo < 0 and lo_in)]
    return out


OPTIONS = numeric_options()


def test_every_command_with_numbers_is_walked():
    commands = {name for name, *_ in OPTIONS}
    assert {"identify", "report", "compare", "simulate", "monitor"} <= commands
    assert len(OPTIONS) >= 45


@pytest.mark.parametrize(("name", "flag", "help_text", "integer"), OPTIONS,
                         ids=[f"{n} {f}" for n, f, *_ in OPTIONS])  # fmt: skip
def test_the_help_states_what_the_code_takes(name, flag, help_text, integer, tmp_path):
    lo, lo_in, hi, hi_in = stated_range(help_text)
    urdf = _urdf_without_rotors(tmp_path)
    context = [a.replace("{urdf}", str(urdf)) for a in CONTEXT.get((name, flag), [])]
    wrong = []
    for value, taken in probes(lo, lo_in, hi, hi_in, integer):
        out = text(wmrid(name, *base_args(name, tmp_path), *context, f"{flag}={value}"))
        first = out.stderr.strip().splitlines()[0] if out.stderr.strip() else ""
        refused = out.returncode == 2 and flag in first
        if refused == taken:
            wrong.append(
                f"{flag} {value}: {'refused' if refused else 'taken'} ({first or 'exit ' + str(out.returncode)})"
            )
    assert not wrong, "\n".join(wrong)
