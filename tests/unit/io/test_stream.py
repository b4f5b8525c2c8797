"""Reading a log piece by piece gives what reading it whole gives, and identify streams it.

Independent computation: :func:`wmrid.io.logs.read_log` of the same file (itself tested against hand
values in test_logio) and the in-memory identify on the arrays.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from locations import ROOT_DIR

from wmrid.core import wheel_log
from wmrid.core.errors import LogFormatError
from wmrid.io.logs import open_log, read_log
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify

SAMPLES = ROOT_DIR / "sample_logs"


def _frame(n: int = 2000, start: float = 0.0) -> pd.DataFrame:
    rng = np.random.default_rng(3)
    t = start + np.arange(n) * 1e-3
    return pd.DataFrame(
        {
            "t": t,
            "eta_r": 3 + np.sin(t) + 0.01 * rng.standard_normal(n),
            "eta_l": 2 + np.cos(t),
            "tau_r": 1 + 0.5 * np.sin(3 * t),
            "tau_l": 0.8 + 0.4 * np.cos(2 * t),
        }
    )


def _same(a, b) -> None:
    assert np.array_equal(a.t, b.t)
    assert np.array_equal(a.eta, b.eta)
    assert np.array_equal(a.tau, b.tau)
    assert a.notes == b.notes


@pytest.mark.parametrize("rows", [7, 1000, 1 << 20])
@pytest.mark.parametrize("name", ["paper_sinusoid.csv", "paper_sinusoid.parquet", "paper_sinusoid.mcap"])
def test_pieces_join_to_the_whole_log(name: str, rows: int) -> None:
    path = str(SAMPLES / name)
    whole = read_log(path)
    stream = open_log(path, rows=rows)
    pieces = list(stream)
    assert all(len(p) == rows for p in pieces[:-1])  # every format cuts exactly ``rows`` rows
    assert 0 < len(pieces[-1]) <= rows
    assert stream.samples == len(whole)
    _same(stream.read(), whole)


POSITIONAL = {"t": "1", "eta_r": "2", "eta_l": "3", "tau_r": "4", "tau_l": "5"}


@pytest.mark.parametrize(
    ("writer", "columns"),
    [
        (lambda f, p: p.write_text("# a comment\n" + f.to_csv(index=False)), None),  # comments: the C engine
        (lambda f, p: p.write_text(f.to_csv(index=False, sep=";", decimal=",")), None),  # decimal commas: C engine
        (lambda f, p: p.write_text(f.to_csv(index=False, header=False)), POSITIONAL),  # no header: C engine
        (lambda f, p: p.write_text(f.to_csv(index=False, sep="\t")), None),  # tabs: pyarrow
    ],
    ids=["comments", "decimal-comma", "headerless", "tabs"],
)
def test_csv_layouts_read_the_same_in_pieces(tmp_path: Path, writer, columns) -> None:
    path = tmp_path / "log.csv"
    writer(_frame(), path)
    whole = read_log(str(path), columns=columns)
    assert len(whole) == 2000
    _same(open_log(str(path), columns=columns, rows=333).read(), whole)


def test_integer_nanoseconds_in_pieces_keep_one_offset(tmp_path: Path) -> None:
    frame = _frame()
    frame["t"] = 1_700_000_000_000_000_000 + np.arange(len(frame), dtype=np.int64) * 1_000_000
    path = tmp_path / "ns.parquet"
    frame.to_parquet(path)
    whole = read_log(str(path))
    assert whole.t[0] == 0.0
    assert whole.t[-1] == pytest.approx(1.999, abs=1e-12)
    _same(open_log(str(path), rows=100).read(), whole)


def test_time_going_back_at_a_piece_boundary_names_its_line(tmp_path: Path) -> None:
    frame = _frame(50)
    frame.loc[20, "t"] = frame.loc[19, "t"]  # row 20 (0-based) repeats the stamp before it: line 22 of the file
    path = tmp_path / "rep.csv"
    frame.to_csv(path, index=False)
    messages = set()
    for rows in (20, 7, 1000):  # row 20 opens the second piece of 20 rows
        with pytest.raises(LogFormatError) as err:
            open_log(str(path), rows=rows).read()
        messages.add(str(err.value))
    assert len(messages) == 1
    assert "line 22" in messages.pop()


@pytest.mark.slow  # a 3 s large CSV
def test_text_late_in_a_plain_csv_falls_back_from_the_row_it_failed_on(tmp_path: Path) -> None:
    # pyarrow infers float64 from its first 16 MB block and refuses "oops" later; the C engine then takes
    # over from the first row not yet handed out and names the line.
    frame = _frame(600_000)
    frame["eta_l"] = frame["eta_l"].astype(object)
    frame.loc[550_000, "eta_l"] = "oops"
    path = tmp_path / "late.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(LogFormatError, match=r"line 550002, column 'eta_l': 'oops' is not a number"):
        open_log(str(path)).read()


def test_a_column_that_turns_from_integers_to_decimals_is_refused(tmp_path: Path) -> None:
    # a comment line sends the file to the C engine, which infers each piece's types on its own
    lines = ["# log", "t,eta_r,eta_l,tau_r,tau_l"] + [f"{i},1,2,{i % 3},1" for i in range(20)] + ["20.5,1,2,1,1"]
    path = tmp_path / "mixed.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogFormatError, match=r"line 23: time stamp 20\.5 has decimals"):
        open_log(str(path), time_unit="ns", rows=10).read()


@pytest.mark.parametrize("cache_rows", [wheel_log.CACHE_ROWS, 0])
def test_identify_on_a_stream_equals_identify_in_memory(monkeypatch, cache_rows: int) -> None:
    # cache_rows 0: the replay reads the file a second time instead of keeping the pieces.
    monkeypatch.setattr(wheel_log, "CACHE_ROWS", cache_rows)
    path = str(SAMPLES / "paper_sinusoid.parquet")
    robot = BUILTIN_ROBOTS["paper"]
    whole = identify(read_log(path), robot)
    streamed = identify(open_log(path, rows=4096), robot)
    for name, (value, std) in whole.parameters.items():
        # bit for bit: the replay does not depend on the piece size, the survey's figures are exact here
        assert streamed.parameters[name] == (value, std), name
    # the rate is 1 / the median of the pieces' median steps: equal to rounding
    assert streamed.log_info.rate_hz == pytest.approx(whole.log_info.rate_hz, rel=1e-12)
    assert replace(streamed.log_info, rate_hz=None) == replace(whole.log_info, rate_hz=None)
    assert np.array_equal(streamed.history.t, whole.history.t)


def test_stream_limits_read_again_instead_of_keeping(tmp_path: Path) -> None:
    """Within ``stream_limits(0)`` a stream keeps nothing after a pass (each pass reads the file again), the same
    samples; a log opened within has pieces of at most the limit; nested or overlapping blocks apply the tightest
    limits, each block's end lifts its own, and the defaults come back after."""
    passes = []

    def pieces():
        passes.append(1)
        yield wheel_log.WheelLog(t=np.arange(3.0), eta=np.ones((3, 2)), tau=np.zeros((3, 2)), source="s")
        return ()

    def twice() -> int:
        passes.clear()
        stream = wheel_log.LogStream("s", "N m", pieces)
        first, second = list(stream), list(stream)
        assert np.array_equal(first[0].t, second[0].t)
        return len(passes)

    assert twice() == 1
    path = str(SAMPLES / "paper_sinusoid.csv")
    with wheel_log.stream_limits(0, piece=1000):
        assert twice() == 2
        assert max(len(p) for p in open_log(path)) == 1000
        with wheel_log.stream_limits(10):  # a looser block within keeps the tighter limits
            assert (wheel_log.cache_rows(), wheel_log.piece_rows()) == (0, 1000)
            assert twice() == 2
        assert (wheel_log.cache_rows(), wheel_log.piece_rows()) == (0, 1000)
    assert (wheel_log.cache_rows(), wheel_log.piece_rows()) == (wheel_log.CACHE_ROWS, wheel_log.CHUNK_ROWS)
    assert max(len(p) for p in open_log(path)) == len(read_log(path).t)  # 40 001 samples: one piece
    # blocks that end in another order than they began (two live runs in threads) lift only their own limits
    first, second = wheel_log.stream_limits(0, piece=500), wheel_log.stream_limits(100, piece=2000)
    first.__enter__()
    second.__enter__()
    first.__exit__(None, None, None)
    assert (wheel_log.cache_rows(), wheel_log.piece_rows()) == (100, 2000)
    second.__exit__(None, None, None)
    assert (wheel_log.cache_rows(), wheel_log.piece_rows()) == (wheel_log.CACHE_ROWS, wheel_log.CHUNK_ROWS)
    with pytest.raises(ValueError, match="piece >= 1"), wheel_log.stream_limits(0, piece=0):
        pass


def test_identify_without_robot_streams_the_same_start(tmp_path: Path) -> None:
    path = str(SAMPLES / "paper_sinusoid.csv")
    whole = identify(read_log(path))
    streamed = identify(open_log(path, rows=999))
    assert np.array_equal(whole.observer_settings.theta_init, streamed.observer_settings.theta_init)
    assert whole.parameters == streamed.parameters


def test_a_file_that_changes_between_passes_is_refused(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(wheel_log, "CACHE_ROWS", 0)
    path = tmp_path / "grow.csv"
    _frame(100).to_csv(path, index=False)
    stream = open_log(str(path), rows=30)
    list(stream)
    _frame(100, start=1.0).iloc[:90].to_csv(path, index=False)
    with pytest.raises(LogFormatError, match="changed while it was read"):
        list(stream)


def _parquet_in_groups(frame: pd.DataFrame, path: Path, group_rows: int) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, row_group_size=group_rows)


@pytest.mark.parametrize("group_rows", [4000, 1000])
def test_the_time_offset_does_not_depend_on_the_row_groups(tmp_path: Path, group_rows: int) -> None:
    # Integer ns stamps starting 2 s below 2**23 s: they cross the float64 1 ns limit within the log. Whatever
    # the row groups, the stamps are stored relative to the first one and keep their exact 1 ms steps.
    frame = _frame(4000)
    frame["t"] = (2**23 - 2) * 10**9 + np.arange(4000, dtype=np.int64) * 1_000_000
    path = tmp_path / "cross.parquet"
    _parquet_in_groups(frame, path, group_rows)
    log = read_log(str(path))
    np.testing.assert_array_equal(log.t, np.arange(4000) * 1_000_000 / 1e9)  # exact, correctly rounded
    assert any("relative to the first stamp" in n for n in log.notes)


@pytest.mark.parametrize("group_rows", [1500, 400, 3000])
def test_leading_zero_stamps_among_epoch_times_are_dropped_whatever_the_row_groups(tmp_path, group_rows):
    frame = _frame(3000)
    frame["t"] = 1_700_000_000.0 + np.arange(3000) * 1e-3
    frame.loc[:1499, "t"] = 0.0  # a clock not yet set for the first 1500 rows
    path = tmp_path / "zeros.parquet"
    _parquet_in_groups(frame, path, group_rows)
    log = read_log(str(path))
    assert len(log) == 1500
    assert any("1500 rows with time stamp 0" in n for n in log.notes)


def test_the_survey_does_not_depend_on_the_pieces(tmp_path: Path) -> None:
    # Uneven steps (1.0 ms then 1.3 ms, 5 % jitter): the median step, the start sample and so the result are
    # the same for any cut of the log.
    rng = np.random.default_rng(7)
    steps = np.where(np.arange(20000) < 12000, 1e-3, 1.3e-3) * rng.uniform(0.95, 1.05, 20000)
    frame = _frame(20001)
    frame["t"] = np.concatenate(([0.0], np.cumsum(steps)))
    path = tmp_path / "jitter.parquet"
    frame.to_parquet(path)
    whole = identify(read_log(str(path)))
    for rows in (5000, 777):
        cut = identify(open_log(str(path), rows=rows))
        assert cut.log_info == whole.log_info
        assert np.array_equal(cut.observer_settings.theta_init, whole.observer_settings.theta_init)
        assert cut.parameters == whole.parameters
