"""A corpus of broken logs: every one must get a clear answer from the real CLI.

The contract (issue "every broken log gets a clear answer"): exit 0 ok, 1 the log does not support a
result, 2 bad usage or unreadable input, 130 interrupted; on failure one line on stderr naming the file,
the place at fault and what to do; never a traceback (without --debug); at most three lines on stderr.

Each case builds its input inside ``tmp_path`` (CSV cases start from the first 2 s of the bundled 1 kHz
``sample_logs/paper_sinusoid.csv`` and break it), runs ``wmrid identify LOG --format json`` through its
entry point (in this process), and checks the exit code, the stderr message, and on success the single JSON object on
stdout with the expected note or warning.
"""

from __future__ import annotations

import json
import math
import random
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cliutil
import pytest
from locations import ROOT_DIR

ROOT = ROOT_DIR
SAMPLE_CSV = ROOT / "sample_logs" / "paper_sinusoid.csv"
BASE_LINES = 2000  # header + 1999 rows: 2 s at 1 kHz
BAD_ROW = 500  # 0-based data row broken by the cell cases: line 502 of the file (header is line 1)
BAD_LINE = BAD_ROW + 2


# Building the inputs


def _base() -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the good small log, as text cells."""
    with open(SAMPLE_CSV, encoding="utf-8") as fh:
        lines = [next(fh).rstrip("\n") for _ in range(BASE_LINES)]
    return lines[0].split(","), [line.split(",") for line in lines[1:]]


def _write_csv(path: Path, header: list[str], rows: list[list[str]], sep: str = ",") -> str:
    path.write_text("\n".join(sep.join(cells) for cells in [header, *rows]) + "\n", encoding="utf-8")
    return str(path)


def _base_frame():
    import pandas as pd

    return pd.read_csv(SAMPLE_CSV, nrows=BASE_LINES - 1)


def _sim_frame(duration: float = 5.0):
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.simulate import simulate

    robot = BUILTIN_ROBOTS["paper"]
    return simulate(robot.reference, robot.nominal, duration=duration).to_frame()


def empty_file(tmp: Path) -> str:
    path = tmp / "empty.csv"
    path.write_bytes(b"")
    return str(path)


def header_only(tmp: Path) -> str:
    header, _ = _base()
    return _write_csv(tmp / "header_only.csv", header, [])


def missing_column(tmp: Path) -> str:
    header, rows = _base()
    j = header.index("tau_l")
    return _write_csv(tmp / "missing_column.csv", header[:j] + header[j + 1 :], [r[:j] + r[j + 1 :] for r in rows])


def misspelled_column(tmp: Path) -> str:
    header, rows = _base()
    header[header.index("tau_l")] = "tua_l"
    return _write_csv(tmp / "misspelled.csv", header, rows)


def _set_cell(name: str, column: str, value: str) -> Callable[[Path], str]:
    def build(tmp: Path) -> str:
        header, rows = _base()
        rows[BAD_ROW][header.index(column)] = value
        return _write_csv(tmp / name, header, rows)

    return build


def time_backwards(tmp: Path) -> str:
    header, rows = _base()
    rows[BAD_ROW][0] = repr(float(rows[BAD_ROW - 1][0]) - 0.0005)
    return _write_csv(tmp / "backwards.csv", header, rows)


def repeated_stamp(tmp: Path) -> str:
    header, rows = _base()
    rows[BAD_ROW][0] = rows[BAD_ROW - 1][0]
    return _write_csv(tmp / "repeated.csv", header, rows)


def hour_jump(tmp: Path) -> str:
    header, rows = _base()
    for row in rows[1000:]:
        row[0] = repr(float(row[0]) + 3600.0)
    return _write_csv(tmp / "hour_jump.csv", header, rows)


def integer_ns(tmp: Path) -> str:
    header, rows = _base()
    for row in rows:
        row[0] = str(1_700_000_000_000_000_000 + round(float(row[0]) * 1e9))
    return _write_csv(tmp / "integer_ns.csv", header, rows)


def single_row(tmp: Path) -> str:
    header, rows = _base()
    return _write_csv(tmp / "single_row.csv", header, rows[:1])


def constant_signals(tmp: Path) -> str:
    header, rows = _base()
    for row in rows:
        row[1:] = ["3.0", "3.0", "1.0", "1.0"]
    return _write_csv(tmp / "constant.csv", header, rows)


def huge_values(tmp: Path) -> str:
    header, rows = _base()
    for row in rows:
        row[1:] = [repr(float(x) * 1e300) for x in row[1:]]
    return _write_csv(tmp / "huge.csv", header, rows)


def semicolon_decimal_comma(tmp: Path) -> str:
    header, rows = _base()
    rows = [[cell.replace(".", ",") for cell in row] for row in rows]
    return _write_csv(tmp / "semicolon.csv", header, rows, sep=";")


def random_bytes(tmp: Path) -> str:
    path = tmp / "random.csv"
    path.write_bytes(random.Random(7).randbytes(8192))
    return str(path)


def a_directory(tmp: Path) -> str:
    path = tmp / "logdir.csv"
    path.mkdir()
    return str(path)


def missing_path(tmp: Path) -> str:
    return str(tmp / "no_such_log.csv")


def truncated_parquet(tmp: Path) -> str:
    from wmrid.io.logs import write_log

    path = tmp / "truncated.parquet"
    write_log(_base_frame(), str(path))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return str(path)


def truncated_mcap(tmp: Path) -> str:
    from wmrid.io.mcap.writer import write_joint_state_mcap

    path = tmp / "truncated.mcap"
    write_joint_state_mcap(path, _sim_frame())
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.6)])
    return str(path)


def text_named_mcap(tmp: Path) -> str:
    path = tmp / "notes.mcap"
    path.write_text("this is not a ROS 2 bag\njust some text someone saved with the wrong name\n", encoding="utf-8")
    return str(path)


def _raw_mcap(path: Path, schema_name: str, schema_encoding: str, msg_encoding: str, schema: bytes) -> str:
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        writer = Writer(fh)
        writer.start(profile="ros2", library="wmrid-tests")
        schema_id = writer.register_schema(schema_name, schema_encoding, schema)
        channel = writer.register_channel("/chatter", msg_encoding, schema_id)
        for i in range(100):
            stamp = 10**18 + i * 10**7
            writer.add_message(channel, log_time=stamp, data=b"\x00\x01\x00\x00hello\x00", publish_time=stamp)
        writer.finish()
    return str(path)


def mcap_without_joint_state(tmp: Path) -> str:
    return _raw_mcap(tmp / "chatter.mcap", "std_msgs/msg/String", "ros2msg", "cdr", b"string data")


def mcap_unknown_encoding(tmp: Path) -> str:
    return _raw_mcap(tmp / "weird.mcap", "sensor_msgs/msg/JointState", "ros2msg", "weird", b"")


def mcap_topics_not_overlapping(tmp: Path) -> str:
    from mcap_ros2.writer import Writer as Ros2Writer

    from wmrid.io.mcap.writer import JOINT_STATE_MSGDEF

    names = ["left_wheel_joint", "right_wheel_joint"]

    def msg(stamp_ns: int, velocity=(), effort=()) -> dict:
        header = {"stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9}, "frame_id": "base_link"}
        return {"header": header, "name": names, "position": [], "velocity": list(velocity), "effort": list(effort)}

    path = tmp / "split.mcap"
    t0 = 1_700_000_000 * 10**9
    with open(path, "wb") as fh:
        writer = Ros2Writer(fh)
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
        for i in range(500):  # speeds over 0..5 s, efforts over 10..15 s
            stamp = t0 + i * 10**7
            speed = [3.0 + math.sin(0.01 * i), 3.0 + math.cos(0.01 * i)]
            writer.write_message("/wheel_state", schema, msg(stamp, velocity=speed), log_time=stamp, publish_time=stamp)
            late = stamp + 10 * 10**9
            torque = [1.0 + math.sin(0.02 * i), 1.0 - math.sin(0.02 * i)]
            writer.write_message("/wheel_cmd", schema, msg(late, effort=torque), log_time=late, publish_time=late)
        writer.finish()
    return str(path)


# The table


@dataclass(frozen=True)
class Case:
    build: Callable[[Path], str]
    args: tuple[str, ...] = ()
    code: int = 2
    stderr: tuple[str, ...] = ()  # substrings all expected in stderr (case-insensitive), on failure
    note: tuple[str, ...] = ()  # on success: one of these expected in a log note or warning (case-insensitive)
    absent: tuple[str, ...] = ()  # on success: none of these in any log note or warning


def good_excerpt(tmp: Path) -> str:
    header, rows = _base()
    return _write_csv(tmp / "good.csv", header, rows)


CASES = [
    # A clean log must not be told its sign convention is reversed (the right wheel brakes a lot in it).
    pytest.param(Case(good_excerpt, code=0, absent=("sign convention",)), id="control-clean-excerpt"),
    pytest.param(Case(empty_file, stderr=("empty",)), id="empty-file"),
    pytest.param(Case(header_only, stderr=("no data",)), id="header-only"),
    pytest.param(Case(missing_column, stderr=("tau_l", "--columns")), id="missing-column"),
    pytest.param(Case(misspelled_column, stderr=("did you mean", "tua_l")), id="misspelled-column"),
    pytest.param(
        Case(_set_cell("text_cell.csv", "tau_r", "abc"), stderr=(f"line {BAD_LINE}", "tau_r", "abc")), id="text-in-cell"
    ),
    pytest.param(Case(_set_cell("nan_cell.csv", "eta_l", "nan"), stderr=(f"line {BAD_LINE}", "eta_l")), id="nan-cell"),
    pytest.param(Case(_set_cell("inf_cell.csv", "tau_l", "inf"), stderr=(f"line {BAD_LINE}", "tau_l")), id="inf-cell"),
    pytest.param(Case(time_backwards, stderr=(f"line {BAD_LINE}", "not strictly increasing", "sort")), id="time-back"),
    pytest.param(Case(repeated_stamp, stderr=(f"line {BAD_LINE}", "repeated")), id="repeated-stamp"),
    # A hole of an hour cannot be bridged by the estimator: refused (exit 1), naming the jump and the fix.
    pytest.param(Case(hour_jump, code=1, stderr=("jumps by 3600", "cut the log")), id="hour-jump"),
    pytest.param(Case(integer_ns, code=0, note=("nanoseconds",)), id="integer-ns"),
    pytest.param(Case(single_row, stderr=("only 1 sample", "longer log")), id="single-row"),
    pytest.param(Case(constant_signals, code=1, stderr=("excit",)), id="constant-signals"),
    # Implausible magnitudes are refused by identify (NotIdentifiableError, exit 1) with a clear message.
    pytest.param(Case(huge_values, code=1, stderr=("4.52e+300", "units")), id="values-1e300"),
    pytest.param(Case(semicolon_decimal_comma, code=0, note=("decimal commas",)), id="semicolon-decimal-comma"),
    pytest.param(Case(random_bytes, stderr=("random.csv",)), id="random-bytes-csv"),
    pytest.param(Case(a_directory, stderr=("folder",)), id="directory"),
    pytest.param(Case(missing_path, stderr=("no_such_log.csv",)), id="missing-path"),
    pytest.param(Case(truncated_parquet, stderr=("parquet",)), id="truncated-parquet"),
    pytest.param(Case(truncated_mcap, code=0, note=("cut short",)), id="truncated-mcap"),
    pytest.param(Case(text_named_mcap, stderr=("mcap",)), id="text-named-mcap"),
    pytest.param(Case(mcap_without_joint_state, stderr=("JointState", "/chatter")), id="mcap-no-jointstate"),
    pytest.param(Case(mcap_unknown_encoding, stderr=("weird",)), id="mcap-unknown-encoding"),
    pytest.param(
        Case(
            mcap_topics_not_overlapping,
            args=("--velocity-topic", "/wheel_state", "--effort-topic", "/wheel_cmd"),
            stderr=("do not overlap", "/wheel_state", "/wheel_cmd"),
        ),
        id="mcap-topics-not-overlapping",
    ),
]


def _finite_numbers(value) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_finite_numbers(v) for v in value.values())
    if isinstance(value, list):
        return all(_finite_numbers(v) for v in value)
    return True


@pytest.mark.parametrize("case", CASES)
def test_broken_log_gets_a_clear_answer(tmp_path, case: Case):
    path = case.build(tmp_path)
    proc = cliutil.text(cliutil.wmrid("identify", path, "--format", "json", *case.args, cwd=tmp_path))
    stderr = proc.stderr
    assert "Traceback" not in stderr, stderr
    assert len(stderr.splitlines()) <= 3, stderr
    assert proc.returncode == case.code, (proc.returncode, stderr)
    if case.code != 0:
        assert proc.stdout == "", proc.stdout[:500]
        assert "internal error" not in stderr, stderr
        assert stderr.startswith("wmrid: "), stderr
        assert Path(path).name in stderr, f"the message does not name the file: {stderr}"
        for text in case.stderr:
            assert text.lower() in stderr.lower(), f"{text!r} not in: {stderr}"
        return
    result, end = json.JSONDecoder().raw_decode(proc.stdout)
    assert isinstance(result, dict)
    assert proc.stdout[end:].strip() == "", "more than one JSON object on stdout"
    said = [*result["log"]["notes"], *result["warnings"]]
    if case.note:
        assert any(n.lower() in s.lower() for n in case.note for s in said), said
    for text in case.absent:
        assert not any(text.lower() in s.lower() for s in said), said
    values = [p.get("value") for p in result["parameters"].values() if isinstance(p, dict)]
    assert values, result["parameters"]
    assert _finite_numbers([v for v in values if v is not None]), f"non-finite parameters: {values}"


def _handlers_installed(pid: int) -> bool:
    """Whether process ``pid`` runs a wmrid command: its signal handlers are in (SIGTERM caught, which Python alone
    does not catch; read from /proc, and True where there is none)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True
    caught = next((line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), None)
    return caught is None or bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


def _interrupted(args: list[str], delay: float, cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    """``wmrid ARGS`` in a subprocess, sent SIGINT ``delay`` s after the command has started (stdin a pipe, left
    open); its outcome.  The delay counts from wmrid's signal handlers being in: a Ctrl-C in Python's own start-up
    and imports is Python's (a traceback), which a loaded machine stretched past 0.5 s."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "wmrid", *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
    )
    try:
        deadline = time.monotonic() + 60
        while proc.poll() is None and not _handlers_installed(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


@pytest.mark.slow  # a real process interrupted (3 s); SIGTERM/SIGHUP stay in the default run
def test_interrupt_exits_130(tmp_path):
    """Ctrl-C while wmrid waits for a log on standard input: exit 130, one short line, no traceback."""
    # 3 s into the command: past its imports, now blocked reading standard input
    proc = _interrupted(["identify", "-", "--format", "json"], 3.0, tmp_path, timeout=120)
    stdout, stderr = proc.stdout, proc.stderr
    assert "Traceback" not in stderr, stderr
    assert len(stderr.splitlines()) <= 3, stderr
    assert proc.returncode == 130, (proc.returncode, stderr)
    assert stdout == ""
    assert "interrupted" in stderr, stderr


@pytest.mark.parametrize(
    "delay",
    [0.5, 1.2, *(pytest.param(d, marks=pytest.mark.slow) for d in (2.0, 3.0, 4.5))],  # the later ones: 2-5 s each
)
def test_interrupt_leaves_no_partial_output(tmp_path, delay):
    """Ctrl-C at some point of `simulate` writing a long log: afterwards the folder holds either nothing or the
    complete log with its truth (they are renamed into place together), never a part or a temporary file."""
    out = tmp_path / "long.parquet"
    # the delays fall before, during and (on a fast machine) after the writing
    args = ["simulate", "-o", str(out), "--duration", "600", "--eta-noise", "0.01"]
    proc = _interrupted(args, delay, tmp_path, timeout=300)
    stderr = proc.stderr
    assert "Traceback" not in stderr, stderr
    assert proc.returncode in (0, 130), (proc.returncode, stderr)
    left = sorted(p.name for p in tmp_path.iterdir())
    if proc.returncode == 0 or left:
        assert left == ["long.parquet", "long.parquet.truth.json"], left
        from wmrid.io.logs import read_log

        assert len(read_log(str(out))) == 600_001
