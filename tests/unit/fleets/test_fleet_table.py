"""The fleet's files (issue 17): the table's schema is stable and round-trips through Parquet, the manifest is read
with its per-log options and refused with its row named, logs are found from folders and globs, and a path states a
robot id and a time."""

from __future__ import annotations

import datetime as dt

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.fleets import manifest as fm, table as ft
from wmrid.fleets.run import option_columns

UTC = dt.timezone.utc
OPTIONS = option_columns()

#: The table's columns as documented in docs/reference/fleet-table.md; a change here is a new schema version.
DOCUMENTED = [
    ("robot_id", "string"), ("log", "string"), ("robot", "string"), ("sha256", "string"), ("bytes", "int64"),
    ("start_time", "timestamp[us, tz=UTC]"), ("time_source", "string"), ("duration_s", "double"),
    ("samples", "int64"), ("rate_hz", "double"), ("method", "string"), ("form", "string"), ("effort_unit", "string"),
    ("options", "string"), ("options_key", "string"),
    *[(c, "double") for n in ft.PARAMETERS for c in (n, f"{n}_std")],
    ("speed_r", "double"), ("speed_l", "double"), ("Fv1_Fd1_corr", "double"), ("Fv2_Fd2_corr", "double"),
    *[(f"payload_{n}{s}", "double") for n in ("mass", "x", "y", "inertia") for s in ("", "_std")],
    ("flags", "list<element: string>"), ("warnings", "list<element: string>"), ("fit_r", "double"), ("fit_l", "double"),
    ("run_time_s", "double"), ("worker", "string"), ("wmrid_version", "string"), ("error", "string"),
]  # fmt: skip


def test_schema_is_stable():
    schema = ft.schema()
    assert [(f.name, str(f.type)) for f in schema] == DOCUMENTED
    assert schema.metadata[b"wmrid_fleet_schema"] == b"3"
    assert ft.PARAMETERS == ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2", "Cv", "Cw")


def test_table_round_trip(tmp_path):
    rows = [
        ft.empty_row(robot_id="R1", log="a.mcap", start_time=dt.datetime(2026, 3, 1, 8, tzinfo=UTC), M11=1.5,
                     M11_std=0.01, flags=["M11"], warnings=["w"], samples=10),
        ft.empty_row(robot_id="R2", log="b.mcap", error="b.mcap: broken"),
    ]  # fmt: skip
    path = tmp_path / "t.parquet"
    ft.write_table(rows, path)
    back = ft.read_table(path)
    assert back == rows
    on_disk = pq.read_schema(path)
    assert [(f.name, str(f.type)) for f in on_disk] == DOCUMENTED
    assert on_disk.metadata[b"wmrid_fleet_schema"] == b"3"
    with pytest.raises(Exception, match="exists"):
        ft.write_table(rows, path)  # never over a table without force
    ft.write_table(rows[:1], path, force=True)
    assert len(ft.read_table(path)) == 1


@pytest.mark.parametrize(("version", "dropped"), [("1", (*ft.ADDED_IN_2, *ft.ADDED_IN_3)), ("2", ft.ADDED_IN_3)])
def test_an_older_table_reads_with_nulls_in_the_columns_added_since(tmp_path, version: str, dropped) -> None:
    """A table written before schema 2 (no speeds, no friction correlations) or 3 (no payload) still reads, resumes
    and reviews: those columns come back null, everything else as written; a newer schema is refused."""
    rows = [ft.empty_row(robot_id="R1", log="a.mcap", M11=1.5, M11_std=0.01, flags=["M11"], samples=10)]
    table = ft.to_arrow(rows).drop_columns(list(dropped))
    old = table.replace_schema_metadata({b"wmrid_fleet_schema": version.encode()})
    path = tmp_path / f"v{version}.parquet"
    pq.write_table(old, path)
    assert ft.read_table(path) == rows
    newer = table.replace_schema_metadata({b"wmrid_fleet_schema": b"4"})
    pq.write_table(newer, tmp_path / "v4.parquet")
    with pytest.raises(LogFormatError, match=r"schema 1, 2 or 3 \(schema 4\)"):
        ft.read_table(tmp_path / "v4.parquet")


def test_an_unknown_row_column_is_refused():
    with pytest.raises(ValueError, match="not columns"):
        ft.empty_row(speed=1.0)  # speed_r and speed_l are columns; "speed" is not


def test_a_parquet_file_that_is_not_a_fleet_table_is_named(tmp_path):
    other = tmp_path / "other.parquet"
    pq.write_table(pa.table({"t": [0.0]}), other)
    with pytest.raises(LogFormatError, match=r"other\.parquet: not a wmrid fleet table"):
        ft.read_table(other)
    with pytest.raises(UsageError, match="no such fleet table"):
        ft.read_table(tmp_path / "none.parquet")
    (tmp_path / "text.parquet").write_text("hello")
    with pytest.raises(LogFormatError, match=r"text\.parquet: not a Parquet fleet table"):
        ft.read_table(tmp_path / "text.parquet")


def test_manifest_rows_with_options(tmp_path):
    (tmp_path / "logs").mkdir()
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "r.toml").write_text("x")
    (tmp_path / "m.csv").write_text(
        "log,robot_id,robot,time,speed_unit,torque_constant,mirror_left\n"
        "logs/a.mcap,R1,robots/r.toml,2026-03-01T08:30:00Z,rpm,0.05,true\n"
        "logs/R9/2026-03-02.mcap,,paper,,,,\n"
        "/abs/c.bag,R3,,1772352000,,,no\n"
    )
    a, b, c = fm.read_manifest(tmp_path / "m.csv", option_names=OPTIONS, root="/")  # /abs/c.bag: outside
    assert a.log == str(tmp_path / "logs" / "a.mcap")
    assert a.robot_id == "R1"
    assert a.robot == str(tmp_path / "robots" / "r.toml")  # relative to the manifest, as the logs
    assert a.time == dt.datetime(2026, 3, 1, 8, 30, tzinfo=UTC)
    assert a.time_source == "manifest"
    assert a.options == {"speed_unit": "rpm", "torque_constant": 0.05, "mirror_left": True}
    assert b.robot_id == "R9"
    assert b.robot == "paper"
    assert b.options == {}
    assert b.time == dt.datetime(2026, 3, 2, tzinfo=UTC)
    assert b.time_source == "path"
    assert c.log == "/abs/c.bag"
    assert c.time == dt.datetime(2026, 3, 1, 8, tzinfo=UTC)
    assert c.options == {"mirror_left": False}


def test_a_manifest_s_true_false_columns_are_read_as_booleans(tmp_path):
    """Every true/false option (read from the option objects' field types: payload, weighted, mirror_left,
    flip_effort) is read as a boolean, so a "false" cell is False (a payload column's "false" was text, which
    ObserverOptions took as true); ObserverOptions and MethodOptions refuse a non-boolean."""
    from wmrid.core.errors import UsageError as Refused
    from wmrid.estimators.options import MethodOptions, ObserverOptions

    (tmp_path / "m.csv").write_text("log,payload,weighted\na.mcap,false,no\nb.mcap,True,1\n")
    a, b = fm.read_manifest(tmp_path / "m.csv", option_names=OPTIONS, root="/")
    assert a.options == {"payload": False, "weighted": False}
    assert b.options == {"payload": True, "weighted": True}
    with pytest.raises(Refused, match="payload must be true or false, got 'false'"):
        ObserverOptions(payload="false")  # type: ignore[arg-type]
    with pytest.raises(Refused, match="weighted must be true or false"):
        MethodOptions(weighted="false")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("path,robot_id\na,b\n", "needs a 'log' column"),
        ("log,speed\na.mcap,1\n", "unknown manifest column.*speed"),
        ("log,time\na.mcap,yesterday\n", r"m\.csv row 2: time: not a time"),
        ("log,k\na.mcap,fast\n", r"m\.csv row 2: k: k must be a number"),
        ("log,weighted\na.mcap,maybe\n", "weighted must be true or false"),
        ("log,payload\na.mcap,sometimes\n", "payload must be true or false"),
        ("log,time\na.mcap,1772352000000\n", "not seconds since 1970"),
        ("log\n\n", "lists no log"),
        ("log,robot_id\n,R1\n", "row 2: the log cell is empty"),
    ],
)
def test_manifest_errors_name_the_row(tmp_path, text, message):
    (tmp_path / "m.csv").write_text(text)
    with pytest.raises(UsageError, match=message):
        fm.read_manifest(tmp_path / "m.csv", option_names=OPTIONS)


def test_parquet_manifest(tmp_path):
    times = pa.array([None, dt.datetime(2026, 2, 1, tzinfo=UTC)], pa.timestamp("us", tz="UTC"))
    table = pa.table({"log": ["x/R5/2026-01-09.csv", "y.csv"], "robot_id": ["R5", "R6"], "k": [20.0, None],
                      "time": times})  # fmt: skip
    pq.write_table(table, tmp_path / "m.parquet")
    entry, other = fm.read_manifest(tmp_path / "m.parquet", option_names=OPTIONS)
    # a null time (NaT in pandas) is an empty cell: the path's date stands
    assert entry.time == dt.datetime(2026, 1, 9, tzinfo=UTC)
    assert entry.time_source == "path"
    assert other.time == dt.datetime(2026, 2, 1, tzinfo=UTC)
    assert other.options == {}
    assert entry.robot_id == "R5"
    assert entry.options == {"k": 20.0}


def test_logs_found_in_folders_and_globs(tmp_path):
    names = ("R1/2026-01-01.mcap", "R1/2026-01-02.csv.gz", "R2/run.parquet", "R2/notes.txt",
             "R2/run.parquet.truth.json", "R3/rec/metadata.yaml", "R3/rec/rec_0.db3", ".hidden/x.mcap")  # fmt: skip
    for name in names:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x")
    found = ft.find_logs([str(tmp_path)])
    assert [p.replace(str(tmp_path) + "/", "") for p in found] == [
        "R1/2026-01-01.mcap", "R1/2026-01-02.csv.gz", "R2/run.parquet", "R3/rec",
    ]  # fmt: skip
    assert ft.find_logs([str(tmp_path / "R*" / "*.mcap")]) == [str(tmp_path / "R1" / "2026-01-01.mcap")]
    # the same log twice (a folder and its file) is one log
    assert len(ft.find_logs([str(tmp_path / "R1"), str(tmp_path / "R1" / "2026-01-01.mcap")])) == 2
    with pytest.raises(UsageError, match="no such file"):
        ft.find_logs([str(tmp_path / "nothing")])
    with pytest.raises(UsageError, match="matches no log"):
        ft.find_logs([str(tmp_path / "*.bag")])
    (tmp_path / "empty").mkdir()
    with pytest.raises(UsageError, match="a folder with no log"):
        ft.find_logs([str(tmp_path / "empty")])


def test_robot_id_and_time_from_the_path():
    assert ft.id_and_time_from_path("fleet/R07/2026-01-05.parquet") == ("R07", dt.datetime(2026, 1, 5, tzinfo=UTC))
    assert ft.id_and_time_from_path("x/amr3/run_2026-01-05T08-30-15.mcap") == (
        "amr3", dt.datetime(2026, 1, 5, 8, 30, 15, tzinfo=UTC))  # fmt: skip
    assert ft.id_and_time_from_path("x/amr3/20260105_083015.bag")[1] == dt.datetime(2026, 1, 5, 8, 30, 15, tzinfo=UTC)
    assert ft.id_and_time_from_path("x/amr3/run.mcap") == ("amr3", None)
    assert ft.id_and_time_from_path("x/amr3/log_20261399.csv") == ("amr3", None)  # digits, not a date
    # the last valid date: a sequence number that reads like no date does not hide the one before it
    assert ft.id_and_time_from_path("R7/2026-03-14_08-30-00_seq00000012.mcap")[1] == dt.datetime(
        2026, 3, 14, 8, 30, tzinfo=UTC)  # fmt: skip
    pattern = r"(?P<robot>bot\d+)_(?P<time>\d{4}-\d\d-\d\d)"
    assert ft.id_and_time_from_path("all/bot12_2026-02-03.mcap", pattern) == (
        "bot12", dt.datetime(2026, 2, 3, tzinfo=UTC))  # fmt: skip
    with pytest.raises(UsageError, match="does not match"):
        ft.id_and_time_from_path("all/other.mcap", pattern)
    with pytest.raises(UsageError, match="no \\(\\?P<robot>"):
        ft.id_and_time_from_path("all/bot12.mcap", r"bot\d+")


def test_content_digest_of_a_file_and_a_folder(tmp_path):
    import hashlib

    (tmp_path / "a.bin").write_bytes(b"abc")
    assert ft.content_digest(str(tmp_path / "a.bin")) == (hashlib.sha256(b"abc").hexdigest(), 3)
    rec = tmp_path / "rec"
    rec.mkdir()
    (rec / "metadata.yaml").write_bytes(b"m")
    (rec / "rec_0.db3").write_bytes(b"dd")
    digest, size = ft.content_digest(str(rec))
    assert size == 3
    assert len(digest) == 64
    (rec / "rec_0.db3").write_bytes(b"de")
    assert ft.content_digest(str(rec))[0] != digest  # any byte of any file changes it


def test_a_delay_gives_one_key_whether_a_number_or_its_text():
    """``wmrid fleet --delay 0.02`` passes the parsed number (the flags are made into ObserverOptions), a CSV manifest
    the text "0.02", a table written before the flags were parsed the text: one "options" cell and one resume key
    for all three ("0.02"), and "auto" however it is spelled."""
    cells = {ft.canonical_options({"delay": v, "k": 5.0}) for v in (0.02, "0.02", " 0.020 ", 2e-2)}
    assert cells == {'{"delay":"0.02","k":5.0}'}
    assert ft.options_key({"delay": 0.02}) == ft.options_key({"delay": "0.02"})
    assert ft.canonical_options({"delay": "Auto"}) == ft.canonical_options({"delay": "auto"}) == '{"delay":"auto"}'
    assert ft.canonical_options({"delay": 0.0}) == ft.canonical_options({"delay": "0"}) == '{"delay":"0"}'
