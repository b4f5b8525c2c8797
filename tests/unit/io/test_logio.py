"""Reading and writing wheel logs: round trips, stdin, delimiters, time units, and every malformed input."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from wmrid.core.errors import LogFormatError, OutputExistsError, UsageError
from wmrid.core.wheel_log import WheelLog
from wmrid.io.logs import read_log, read_metadata, write_log
from wmrid.io.sources import detect_format
from wmrid.io.stamps import seconds_from_stamps
from wmrid.io.table.columns import parse_column_mapping
from wmrid.io.table.csv_log import sniff_delimiter

HEADER = "t,eta_r,eta_l,tau_r,tau_l\n"


def make_frame(n: int = 50, seed: int = 0, pose: bool = True) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    frame = pd.DataFrame(
        {
            "t": 0.1 + np.arange(n) * 1e-3,
            "eta_r": rng.normal(size=n),
            "eta_l": rng.normal(size=n) * 1e-9,
            "tau_r": rng.normal(size=n) * 1e200,
            "tau_l": rng.normal(size=n),
        }
    )
    if pose:
        frame["x"] = rng.normal(size=n)
        frame["y"] = rng.normal(size=n)
        frame["phi"] = rng.normal(size=n)
        frame["theta_r"] = rng.normal(size=n)  # an extra column, ignored
    return frame


def rows(n: int, t0: float = 0.0, sep: str = ",") -> str:
    return "".join(sep.join([repr(t0 + i * 0.01), str(i), str(-i), "0.5", "0.25"]) + "\n" for i in range(n))


def assert_matches(log: WheelLog, frame: pd.DataFrame) -> None:
    """Bit-for-bit equality of every canonical column."""
    np.testing.assert_array_equal(log.t, frame["t"].to_numpy())
    np.testing.assert_array_equal(log.eta, frame[["eta_r", "eta_l"]].to_numpy())
    np.testing.assert_array_equal(log.tau, frame[["tau_r", "tau_l"]].to_numpy())


def log_error(path, **kwargs) -> str:
    """The message of the LogFormatError that reading ``path`` raises; it must be one line."""
    with pytest.raises(LogFormatError) as info:
        read_log(str(path), **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# ---- Round trips


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".tsv", ".pq"])
def test_round_trip_is_exact(tmp_path, suffix):
    frame = make_frame()
    path = tmp_path / f"log{suffix}"
    write_log(frame, str(path))
    log = read_log(str(path))
    assert_matches(log, frame)
    np.testing.assert_array_equal(log.pose, frame[["x", "y", "phi"]].to_numpy())
    assert len(log) == 50
    assert log.duration == frame["t"].iloc[-1] - frame["t"].iloc[0]
    assert log.source == str(path)
    assert log.t.dtype == np.float64
    assert log.eta.shape == log.tau.shape == (50, 2)


def test_round_trip_keeps_integral_float_time_as_seconds(tmp_path):
    """Floats such as 3.0 are written as 3.0, so a float time column never reads back as integer ns."""
    frame = make_frame(pose=False).assign(t=np.arange(50, dtype=np.float64))
    write_log(frame, str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"))
    assert_matches(log, frame)
    assert log.notes == ()
    assert (tmp_path / "log.csv").read_text().splitlines()[1].startswith("0.0,")


float64_bits = st.integers(0, 2**64 - 1).map(lambda b: float(np.uint64(b).view(np.float64)))


@pytest.mark.parametrize("style", ["write_log", "semicolon-decimal-comma", "whitespace"])
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    values=st.lists(float64_bits.filter(np.isfinite), min_size=40, max_size=40),
    # A stamp of exactly 0 among clock times is a documented bad-stamp case (dropped), not a parsing one.
    times=st.lists(st.floats(-1e12, 1e12).filter(lambda x: x != 0.0), min_size=10, max_size=10, unique=True),
)
def test_csv_round_trip_is_bit_exact_for_any_float(tmp_path_factory, style, values, times):
    """Both parsers (pyarrow for plain CSV, pandas' C engine for the others) read repr floats exactly."""
    n = len(times)
    v = np.array(values).reshape(4, 10)
    frame = pd.DataFrame({"t": np.sort(np.array(times)), "eta_r": v[0], "eta_l": v[1], "tau_r": v[2], "tau_l": v[3]})
    path = tmp_path_factory.mktemp("prop") / "log.csv"
    if style == "write_log":
        write_log(frame, str(path))
    elif style == "semicolon-decimal-comma":
        frame.to_csv(path, sep=";", decimal=",", index=False)
    else:
        frame.to_csv(path, sep=" ", index=False)
    log = read_log(str(path))
    assert len(log) == n
    assert log.t.tobytes() == frame["t"].to_numpy().tobytes()
    assert log.eta.tobytes() == frame[["eta_r", "eta_l"]].to_numpy().tobytes()
    assert log.tau.tobytes() == frame[["tau_r", "tau_l"]].to_numpy().tobytes()


def test_parquet_metadata_round_trip(tmp_path):
    path = tmp_path / "log.parquet"
    write_log(make_frame(), str(path), metadata={"wmrid_truth": '{"m": 1.5}'})
    assert read_metadata(str(path)) == {"wmrid_truth": '{"m": 1.5}'}
    write_log(make_frame(), str(tmp_path / "log.csv"), metadata={"ignored": "yes"})
    assert read_metadata(str(tmp_path / "log.csv")) == {}


def test_write_log_refuses_to_overwrite_without_force(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("keep me")
    with pytest.raises(OutputExistsError, match="force=True"):
        write_log(make_frame(), str(path))
    assert path.read_text() == "keep me"
    write_log(make_frame(), str(path), force=True)
    assert_matches(read_log(str(path)), make_frame())
    assert [p.name for p in tmp_path.iterdir()] == ["log.csv"]


def test_write_log_unknown_suffix(tmp_path):
    with pytest.raises(UsageError, match=r"\.csv or \.parquet"):
        write_log(make_frame(), str(tmp_path / "log.xlsx"))
    assert list(tmp_path.iterdir()) == []


def run_python(code: str, stdin: bytes, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], input=stdin, capture_output=True, cwd=cwd, timeout=120)


def test_write_log_dash_writes_csv_to_stdout(tmp_path):
    make_frame().to_parquet(tmp_path / "in.parquet")
    code = "import pandas as pd; from wmrid.io.logs import write_log; write_log(pd.read_parquet('in.parquet'), '-')"
    out = run_python(code, b"", tmp_path)
    assert out.returncode == 0, out.stderr.decode()
    (tmp_path / "out.csv").write_bytes(out.stdout)
    assert_matches(read_log(str(tmp_path / "out.csv")), make_frame())


# ---- Standard input

STDIN_CODE = (
    "import json; from wmrid.io.logs import read_log; log = read_log('-'); "
    "print(json.dumps({'t': log.t.tolist(), 'eta': log.eta.tolist(), 'tau': log.tau.tolist(), "
    "'source': log.source, 'notes': list(log.notes)}))"
)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_read_from_stdin(tmp_path, suffix):
    frame = make_frame()
    path = tmp_path / f"log{suffix}"
    write_log(frame, str(path))
    out = run_python(STDIN_CODE, path.read_bytes(), tmp_path)
    assert out.returncode == 0, out.stderr.decode()
    got = json.loads(out.stdout)
    assert got["source"] == "<stdin>"
    assert np.array_equal(got["t"], frame["t"].to_numpy())
    assert np.array_equal(got["eta"], frame[["eta_r", "eta_l"]].to_numpy())
    assert np.array_equal(got["tau"], frame[["tau_r", "tau_l"]].to_numpy())


@pytest.mark.parametrize(
    ("stdin", "expected"),
    [(b"", "standard input is empty"), (b"\x89MCAP0\r\n" + b"\0" * 64, "no Header record follows")],
)
def test_stdin_errors(tmp_path, stdin, expected):
    code = (
        "from wmrid.io.logs import read_log\nfrom wmrid.core.errors import LogFormatError\n"
        "try:\n    read_log('-')\nexcept LogFormatError as err:\n    print(err)"
    )
    out = run_python(code, stdin, tmp_path)
    assert out.returncode == 0, out.stderr.decode()
    assert expected in out.stdout.decode()
    assert "<stdin>" in out.stdout.decode()


# ---- Format detection and delimiters


@pytest.mark.parametrize(
    ("path", "head", "kind"),
    [
        ("a.csv", b"PAR1", "csv"),
        ("a.TXT", b"", "csv"),
        ("a.tsv", b"", "csv"),
        ("a.parquet", b"t,eta", "parquet"),
        ("a.pq", b"", "parquet"),
        ("a.mcap", b"", "mcap"),
        ("-", b"PAR1\x15\x04", "parquet"),
        ("-", b"\x89MCAP0\r\n", "mcap"),
        ("-", b"t,eta_r", "csv"),
        ("a.log", b"PAR1", "parquet"),
        ("a.dat", b"t eta_r", "csv"),
    ],
)
def test_detect_format(path, head, kind):
    assert detect_format(path, head) == kind


def test_unknown_suffix_is_sniffed(tmp_path):
    frame = make_frame()
    write_log(frame, str(tmp_path / "log.parquet"))
    (tmp_path / "log.bin").write_bytes((tmp_path / "log.parquet").read_bytes())
    assert_matches(read_log(str(tmp_path / "log.bin")), frame)
    write_log(frame, str(tmp_path / "log.csv"))
    (tmp_path / "log.dat").write_bytes((tmp_path / "log.csv").read_bytes())
    assert_matches(read_log(str(tmp_path / "log.dat")), frame)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("t,a,b\n1,2,3\n", (",", ".")),
        ("t;a;b\n1.5;2;3\n", (";", ".")),
        ("t;a;b\n1,5;2;3\n", (";", ",")),
        ("t\ta b\n1\t2 3\n", ("\t", ".")),
        ("t  a   b\n 1 2  3\n", (r"\s+", ".")),
        ("t\n1\n", (",", ".")),
        ('t,"a;b",c\n1,2,3\n', (",", ".")),
    ],
)
def test_sniff_delimiter(text, expected):
    assert sniff_delimiter(text) == expected


def test_semicolon_with_decimal_commas(tmp_path):
    frame = make_frame(pose=False)
    frame.to_csv(tmp_path / "log.csv", sep=";", decimal=",", index=False)
    log = read_log(str(tmp_path / "log.csv"))
    assert_matches(log, frame)
    assert any("decimal commas" in note for note in log.notes)


def test_semicolon_with_decimal_points(tmp_path):
    frame = make_frame(pose=False)
    frame.to_csv(tmp_path / "log.csv", sep=";", index=False)
    log = read_log(str(tmp_path / "log.csv"))
    assert_matches(log, frame)
    assert log.notes == ("columns separated by ';'",)


def test_whitespace_delimited(tmp_path):
    frame = make_frame(pose=False)
    lines = ["  t   eta_r  eta_l tau_r    tau_l  "]
    lines += ["   ".join(repr(float(v)) for v in row) + "  " for row in frame.to_numpy()]
    (tmp_path / "log.txt").write_text("\n".join(lines) + "\n")
    log = read_log(str(tmp_path / "log.txt"))
    assert_matches(log, frame)
    assert "columns separated by whitespace" in log.notes


def test_tab_delimited_with_bom_and_crlf(tmp_path):
    frame = make_frame(pose=False)
    text = frame.to_csv(sep="\t", index=False, lineterminator="\r\n")
    (tmp_path / "log.csv").write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert_matches(read_log(str(tmp_path / "log.csv")), frame)


def test_spaces_after_commas(tmp_path):
    frame = make_frame(pose=False)
    text = frame.to_csv(sep=",", index=False).replace(",", ", ")
    (tmp_path / "log.csv").write_text(text)
    assert_matches(read_log(str(tmp_path / "log.csv")), frame)


def test_latin1_header_is_read_with_a_note(tmp_path):
    frame = make_frame(pose=False).assign(**{"temp_°C": 20.0})
    (tmp_path / "log.csv").write_bytes(frame.to_csv(index=False).encode("latin-1"))
    log = read_log(str(tmp_path / "log.csv"))
    assert_matches(log, frame)
    assert any("Latin-1" in note for note in log.notes)


# ---- Column mapping


def test_parse_column_mapping():
    assert parse_column_mapping("t=time, eta_r=vel_right,tau_l=effort_left") == {
        "t": "time",
        "eta_r": "vel_right",
        "tau_l": "effort_left",
    }
    assert parse_column_mapping("x=pos x,") == {"x": "pos x"}


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("time=t", "'time' is not a column wmrid knows"),
        ("eta_R=vel", "did you mean 'eta_r'?"),
        ("t", "NAME=COLUMN"),
        ("t=", "NAME=COLUMN"),
        ("=time", "NAME=COLUMN"),
        ("t=a,t=b", "given twice"),
        ("", "empty"),
    ],
)
def test_parse_column_mapping_errors(text, expected):
    with pytest.raises(UsageError) as info:
        parse_column_mapping(text)
    assert expected in str(info.value)
    assert "\n" not in str(info.value)


def test_read_with_column_mapping(tmp_path):
    frame = make_frame(pose=False)
    renamed = frame.rename(columns={"t": "time", "eta_r": "vel_right", "tau_l": "effort_left"})
    for suffix in (".csv", ".parquet"):
        path = tmp_path / f"log{suffix}"
        write_log(renamed, str(path))
        mapping = parse_column_mapping("t=time,eta_r=vel_right,tau_l=effort_left")
        log = read_log(str(path), columns=mapping)
        assert_matches(log, frame)
        assert any("eta_r = 'vel_right'" in note for note in log.notes)


def test_mapping_can_swap_wheels(tmp_path):
    frame = make_frame(pose=False)
    write_log(frame, str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"), columns={"eta_r": "eta_l", "eta_l": "eta_r"})
    np.testing.assert_array_equal(log.eta, frame[["eta_l", "eta_r"]].to_numpy())


def test_mapping_with_unknown_key_is_a_usage_error(tmp_path):
    write_log(make_frame(), str(tmp_path / "log.csv"))
    with pytest.raises(UsageError, match="'speed' is not a column"):
        read_log(str(tmp_path / "log.csv"), columns={"speed": "eta_r"})


def test_pose_is_optional(tmp_path):
    frame = make_frame(pose=False)
    write_log(frame.assign(x=1.0, y=2.0), str(tmp_path / "log.csv"))  # no phi: no pose
    assert read_log(str(tmp_path / "log.csv")).pose is None


def test_bad_pose_is_dropped_with_a_note(tmp_path):
    frame = make_frame()
    frame.loc[3, "y"] = np.nan
    write_log(frame, str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"))
    assert log.pose is None
    assert any("pose columns ignored: line 5, column 'y'" in note for note in log.notes)


# ---- Time units

EPOCH_NS = 1_700_000_000_123_456_789


def test_integer_epoch_nanoseconds(tmp_path):
    k = np.arange(50, dtype=np.int64)
    stamps = EPOCH_NS + k * 1_000_001
    frame = make_frame(pose=False).assign(t=stamps)
    for suffix in (".csv", ".parquet"):
        path = tmp_path / f"log{suffix}"
        write_log(frame, str(path))
        log = read_log(str(path))
        np.testing.assert_array_equal(log.t, (k * 1_000_001).astype(np.float64) / 1e9)  # exact
        assert any("integer nanoseconds" in note for note in log.notes)
        assert any(f"relative to the first stamp {EPOCH_NS} ns" in note for note in log.notes)


def test_small_integer_nanoseconds_stay_absolute(tmp_path):
    stamps = 5_000_000 + np.arange(50, dtype=np.int64) * 1_000_000
    write_log(make_frame(pose=False).assign(t=stamps), str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"))
    np.testing.assert_array_equal(log.t, stamps / 1e9)
    assert not any("relative" in note for note in log.notes)


def test_integer_whole_seconds_are_refused_with_the_unit_to_give(tmp_path):
    """Integers 1 apart read as ns are a 1 GHz log: refused, naming the units that make sense of the step, ms (1 kHz)
    or s (1 Hz) (was a note, and m11 = 0)."""
    write_log(make_frame(pose=False).assign(t=np.arange(50)), str(tmp_path / "log.csv"))
    with pytest.raises(LogFormatError, match=r"--time-unit ms \(1e\+03 Hz\) or --time-unit s \(1 Hz\)") as info:
        read_log(str(tmp_path / "log.csv"))
    assert "\n" not in str(info.value)
    log = read_log(str(tmp_path / "log.csv"), time_unit="s")
    np.testing.assert_array_equal(log.t, np.arange(50.0))


@pytest.mark.parametrize(("step", "unit"), [(1, "ms"), (10, "ms"), (1000, "us"), (5000, "us")])
def test_integer_epoch_milliseconds_or_microseconds_are_refused_with_their_unit(tmp_path, step, unit):
    """The issue's case: integer epoch milliseconds (1 ms steps at 1 kHz) were read as nanoseconds, 1 ns apart, and
    identified to m11 = 0 with only a note; now refused, naming the unit that makes the steps 0.1 ms to 1 s."""
    stamps = 1_700_000_000_000 * (1000 if unit == "us" else 1) + np.arange(50, dtype=np.int64) * step
    write_log(make_frame(pose=False).assign(t=stamps), str(tmp_path / "log.csv"))
    with pytest.raises(LogFormatError, match=f"--time-unit {unit}"):
        read_log(str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"), time_unit=unit)
    assert np.median(np.diff(log.t)) == pytest.approx(step * {"ms": 1e-3, "us": 1e-6}[unit])


@pytest.mark.parametrize(("unit", "scale"), [("ms", 1e3), ("us", 1e6), ("ns", 1e9), ("s", 1.0)])
def test_explicit_time_unit_on_floats(tmp_path, unit, scale):
    t = 0.5 + np.arange(50) * 0.25
    write_log(make_frame(pose=False).assign(t=t), str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"), time_unit=unit)
    np.testing.assert_array_equal(log.t, t / scale)


def test_epoch_milliseconds_as_integers_are_made_relative(tmp_path):
    stamps = 1_700_000_000_123 + np.arange(50, dtype=np.int64) * 10
    write_log(make_frame(pose=False).assign(t=stamps), str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"), time_unit="ms")
    np.testing.assert_array_equal(log.t, np.arange(50) * 10 / 1e3)
    assert any("relative to the first stamp 1700000000123 ms" in note for note in log.notes)


def test_float_epoch_seconds_are_kept_as_in_the_file(tmp_path):
    t = 1.7e9 + np.arange(50) * 0.0078125
    write_log(make_frame(pose=False).assign(t=t), str(tmp_path / "log.csv"))
    log = read_log(str(tmp_path / "log.csv"))
    np.testing.assert_array_equal(log.t, t)
    assert log.notes == ()


def test_parquet_timestamp_column(tmp_path):
    base = np.datetime64("2024-05-01T12:00:00.000001", "us")
    stamps = base + np.arange(50) * np.timedelta64(1000, "us")
    frame = make_frame(pose=False)
    table = pa.table({**{c: frame[c].to_numpy() for c in frame}, "t": pa.array(stamps, pa.timestamp("us"))})
    pq.write_table(table, tmp_path / "log.parquet")
    log = read_log(str(tmp_path / "log.parquet"))
    np.testing.assert_array_equal(log.t, (np.arange(50) * 1000.0) / 1e6)  # relative, correctly rounded
    assert any("timestamp[us]" in note for note in log.notes)


def test_time_unit_is_checked():
    with pytest.raises(UsageError, match="time_unit"):
        read_log("whatever.csv", time_unit="min")


@settings(max_examples=200, deadline=None)
@given(
    start=st.integers(-(2**62), 2**62),
    steps=st.lists(st.integers(1, 10**12), min_size=1, max_size=20),
    unit=st.sampled_from(["s", "ms", "us", "ns"]),
)
def test_seconds_from_integer_stamps(start, steps, unit):
    stamps = np.array([start, *(start + np.cumsum(steps))], dtype=object)
    if stamps.max() >= 2**63:
        return
    stamps = stamps.astype(np.int64)
    t, offset = seconds_from_stamps(stamps, unit)
    per_second = {"s": 1, "ms": 10**3, "us": 10**6, "ns": 10**9}[unit]
    relative = offset is not None
    assert relative == (max(abs(int(stamps[0])), abs(int(stamps[-1]))) >= 2**23 * per_second)
    base = int(stamps[0]) if relative else 0
    # correctly rounded: the float nearest to (stamp - base) / per_second
    expected = np.array([float(np.float64(int(s) - base) / per_second) for s in stamps])
    np.testing.assert_array_equal(t, expected)
    if relative and int(stamps[-1]) - int(stamps[0]) < 2**53:
        assert (np.diff(t) >= 0).all()


# ---- Errors: each names the file and the row or column at fault, on one line


def test_missing_file(tmp_path):
    (tmp_path / "run_01.csv").write_text(HEADER + rows(12))
    message = log_error(tmp_path / "run_1.csv")
    assert "run_1.csv: no such file" in message
    assert "run_01.csv" in message


def test_directory(tmp_path):
    """A folder is read when it holds a recording (tests/unit/io/test_bags.py); an empty one is named as such."""
    assert "a folder with no recording in it" in log_error(tmp_path)


def test_empty_file(tmp_path):
    (tmp_path / "empty.csv").write_bytes(b"")
    assert "empty.csv: the file is empty" in log_error(tmp_path / "empty.csv")
    (tmp_path / "blank.csv").write_text("\n \n\n")
    assert "blank.csv: the file holds only blank lines" in log_error(tmp_path / "blank.csv")


def test_header_only(tmp_path):
    (tmp_path / "h.csv").write_text(HEADER)
    assert "h.csv: has a header but no data rows" in log_error(tmp_path / "h.csv")
    pq.write_table(pa.Table.from_pandas(make_frame().iloc[:0], preserve_index=False), tmp_path / "h.parquet")
    assert "h.parquet: the Parquet file has no rows" in log_error(tmp_path / "h.parquet")


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_missing_column(tmp_path, suffix):
    frame = make_frame(pose=False).rename(columns={"eta_r": "Eta_R", "tau_l": "effort"})
    path = tmp_path / f"log{suffix}"
    write_log(frame, str(path))
    message = log_error(path)
    assert message.startswith(f"{path}: no columns 'eta_r' (did you mean 'Eta_R'?), 'tau_l';")
    assert "the columns are 't', 'Eta_R', 'eta_l', 'tau_r', 'effort'" in message
    assert "columns eta_r=Eta_R,tau_l=..." in message  # a library call: the option's Python name


def test_missing_mapped_column(tmp_path):
    write_log(make_frame(pose=False), str(tmp_path / "log.csv"))
    message = log_error(tmp_path / "log.csv", columns={"t": "time"})
    assert "no column 'time' (given for t by --columns)" in message
    assert "columns t=" in message


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (rows(5) + "0.05,abc,1,1,1\n" + rows(10, 1.0), "line 7, column 'eta_r': 'abc' is not a number"),
        (rows(5) + "0.05,1,,1,1\n" + rows(10, 1.0), "line 7, column 'eta_l' is empty or NaN"),
        (rows(5) + "0.05,1,1,NaN,1\n" + rows(10, 1.0), "line 7, column 'tau_r' is empty or NaN"),
        (rows(5) + "0.05,1,1,1,-inf\n" + rows(10, 1.0), "line 7, column 'tau_l' is -inf"),
        (rows(5) + "0.05,1,1,1\n" + rows(10, 1.0), "line 7, column 'tau_l' is empty or NaN"),
        (rows(5) + rows(10, 0.04), "time is not strictly increasing at line 7: 't' = 0.04 follows 0.04"),
        (rows(5) + rows(10, 0.02), "at line 7: 't' = 0.02 follows 0.04"),
        (rows(5) + "1,2,3,4,5,6\n" + rows(10, 1.0), "Expected 5 fields in line 7, saw 6"),
        (rows(9), "only 9 samples; identification needs at least 10"),
        ("\n" + rows(3) + "\n\n" + "0.05,x,1,1,1\n" + rows(10, 1.0), "line 8, column 'eta_r': 'x' is not a number"),
    ],
)
def test_bad_cells_in_csv(tmp_path, body, expected):
    path = tmp_path / "bad.csv"
    path.write_text(HEADER + body)
    message = log_error(path)
    assert message.startswith(f"{path}: ")
    assert expected in message


def test_bad_cells_in_whitespace_csv(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text(HEADER.replace(",", " ") + rows(5, sep=" ") + "0.05 1 1 1 oops\n" + rows(10, 1.0, sep=" "))
    assert "line 7, column 'tau_l': 'oops' is not a number" in log_error(path)


def test_first_bad_row_wins_across_columns(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text(HEADER + rows(3) + "0.03,1,1,1,nan\n" + "0.04,nan,1,1,1\n" + rows(10, 1.0))
    assert "line 5, column 'tau_l'" in log_error(path)


def test_bad_cells_in_parquet(tmp_path):
    frame = make_frame(pose=False)
    frame.loc[6, "eta_l"] = np.inf
    write_log(frame, str(tmp_path / "inf.parquet"))
    assert "inf.parquet: row 7, column 'eta_l' is inf" in log_error(tmp_path / "inf.parquet")

    frame = make_frame(pose=False)
    frame.loc[11, "t"] = frame.loc[10, "t"]
    write_log(frame, str(tmp_path / "dup.parquet"))
    assert "dup.parquet: time is not strictly increasing at row 12" in log_error(tmp_path / "dup.parquet")

    table = pa.Table.from_pandas(make_frame(pose=False), preserve_index=False)
    table = table.set_column(1, "eta_r", pa.array(["1.5"] * 20 + ["fast"] + ["2"] * 29))
    pq.write_table(table, tmp_path / "text.parquet")
    assert "text.parquet: row 21, column 'eta_r': 'fast' is not a number" in log_error(tmp_path / "text.parquet")

    table = pa.Table.from_pandas(make_frame(pose=False), preserve_index=False)
    table = table.set_column(3, "tau_r", pa.array([1.0] * 30 + [None] * 20))
    pq.write_table(table, tmp_path / "null.parquet")
    assert "null.parquet: row 31, column 'tau_r' is empty or NaN" in log_error(tmp_path / "null.parquet")


@pytest.mark.parametrize("cut", ["half", "footer", "garbage"])
def test_unreadable_parquet(tmp_path, cut):
    write_log(make_frame(), str(tmp_path / "good.parquet"))
    data = (tmp_path / "good.parquet").read_bytes()
    broken = {
        "half": data[: len(data) // 2],
        "footer": data[:-3],
        "garbage": data[:4] + bytes(range(256)) * 4 + data[4 + 1024 :],
    }[cut]
    path = tmp_path / "broken.parquet"
    path.write_bytes(broken)
    message = log_error(path)
    assert message.startswith(f"{path}: not a readable Parquet file")


@pytest.mark.parametrize(
    "data",
    [np.random.default_rng(7).bytes(5000), bytes(range(128, 256)) * 40, "t,eta_r\n1,é\n".encode("utf-16")],
)
def test_random_bytes_named_csv(tmp_path, data):
    path = tmp_path / "noise.csv"
    path.write_bytes(data)
    message = log_error(path)
    assert message.startswith(f"{path}: not a CSV text file (byte ")


def test_parquet_bytes_named_csv(tmp_path):
    write_log(make_frame(), str(tmp_path / "log.parquet"))
    (tmp_path / "log.csv").write_bytes((tmp_path / "log.parquet").read_bytes())
    assert "holds PARQUET data, not CSV text; rename it with a .parquet suffix" in log_error(tmp_path / "log.csv")


def test_mcap_magic_without_a_header_record_is_a_clear_error(tmp_path):
    (tmp_path / "run.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(100))
    assert "run.mcap: starts like an MCAP file but no Header record follows" in log_error(tmp_path / "run.mcap")


# ---- Inputs are never modified


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_input_is_unchanged_after_reading(tmp_path, suffix):
    path = tmp_path / f"log{suffix}"
    write_log(make_frame(), str(path))
    os.utime(path, ns=(1_600_000_000_000_000_000, 1_600_000_000_000_000_000))
    path.chmod(0o444)
    before = path.read_bytes()
    mtime = path.stat().st_mtime_ns
    read_log(str(path))
    read_log(str(path), columns={"eta_r": "eta_l"})
    assert path.read_bytes() == before
    assert path.stat().st_mtime_ns == mtime
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_wheel_log_checks_shapes():
    t = np.arange(3.0)
    with pytest.raises(ValueError, match=r"eta must have shape \(3, 2\)"):
        WheelLog(t=t, eta=np.zeros((3, 3)), tau=np.zeros((3, 2)), source="x")
    log = WheelLog(t=t, eta=np.zeros((3, 2)), tau=np.zeros((3, 2)), source="x")
    assert len(log) == 3
    assert log.duration == 2.0
    assert log.pose is None


def test_leading_comment_lines_and_headerless_columns(tmp_path):
    # The REGBOT layout: '%' lines describe the columns by number; the data rows have no header.
    lines = ["%% logfile from robot", "%  1    time 0.003 sec", "%  2  3 Wheel velocity left, right"]
    lines += [f"{0.01 * i:.3f} {1.0 + i:.4f} {2.0 + i:.4f} {0.5:.3f} {0.25:.3f} " for i in range(20)]
    path = tmp_path / "robot.txt"
    path.write_text("\n".join(lines) + "\n")
    log = read_log(str(path), columns={"t": "1", "eta_l": "2", "eta_r": "3", "tau_l": "4", "tau_r": "5"})
    np.testing.assert_array_equal(log.eta[:2], [[2.0, 1.0], [3.0, 2.0]])
    np.testing.assert_array_equal(log.tau[0], [0.25, 0.5])
    assert any("first 3 lines are comments" in n for n in log.notes)
    assert any("no header row" in n for n in log.notes)
    # Errors point at the file's own line numbers, comments counted.
    bad = [*lines[:10], "0.070 x 2 3 4", *lines[11:]]
    path.write_text("\n".join(bad) + "\n")
    assert "line 11" in log_error(path, columns={"t": "1", "eta_l": "2", "eta_r": "3", "tau_l": "4", "tau_r": "5"})


def test_zero_stamps_among_epoch_times_are_dropped_and_float_ns_is_recognised(tmp_path):
    t = 1.7e18 + np.arange(30) * 1e7  # float nanoseconds since the epoch, 100 Hz
    frame = make_frame(30, pose=False)
    frame["t"] = t
    frame.loc[0, "t"] = 0.0
    path = tmp_path / "clock.parquet"
    write_log(frame, str(path))
    log = read_log(str(path))
    assert len(log) == 29
    np.testing.assert_allclose(np.diff(log.t), 0.01, atol=3e-7)  # float64 spacing at 1.7e18 ns is 256 ns
    assert any("time stamp 0" in n and "row 1" in n for n in log.notes)
    assert any("read as ns since the Unix epoch" in n for n in log.notes)


def test_integer_nanoseconds_judged_on_the_whole_log_not_its_first_piece(tmp_path):
    """A 1 kHz log in integer ns whose first Parquet row group holds 2 rows 2 us apart was refused (the check used the
    first piece's median step); the whole log's mean step decides."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    stamps = np.concatenate([[0, 2_000], 1_000_000 + np.arange(200, dtype=np.int64) * 1_000_000])
    frame = make_frame(pose=False)
    n = len(stamps)
    table = pa.table({"t": stamps, **{c: np.resize(frame[c].to_numpy(), n) for c in ("eta_r", "eta_l", "tau_r",
                                                                                    "tau_l")}})  # fmt: skip
    path = tmp_path / "groups.parquet"
    with pq.ParquetWriter(path, table.schema) as writer:
        writer.write_table(table.slice(0, 2))
        writer.write_table(table.slice(2))
    log = read_log(str(path))
    assert len(log.t) == n


def test_epoch_microseconds_at_20_khz_suggest_microseconds(tmp_path):
    """20 kHz epoch microseconds (steps of 50): the unit suggested is the one that makes the first stamp a date (it
    said ms, 20 Hz)."""
    stamps = 1_700_000_000_000_000 + np.arange(50, dtype=np.int64) * 50
    write_log(make_frame(pose=False).assign(t=stamps), str(tmp_path / "log.csv"))
    with pytest.raises(LogFormatError, match=r"--time-unit us \(2e\+04 Hz\)"):
        read_log(str(tmp_path / "log.csv"))
