"""Reliability, round three (issue 30), second half: field paths that name message fields only; a full standard
output; outputs of a run stopped by a signal; Markdown reports that escape what came from an input; MuJoCo's own
warnings; forged dates drawn quietly; fleet failures said on stderr; a read-only install.

Real files, real processes and real signals; ``/dev/full`` stands in for a full filesystem.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from locations import ROOT_DIR

from tests import bagutil
from tests.cliutil import assert_clean_error, wmrid

ROOT = ROOT_DIR
SAMPLE_MCAP = ROOT / "sample_logs" / "paper_sinusoid.mcap"

# ---------------------------------------------------------------------------------------------------------------
# Field paths name message fields and selectors only


def _columns(eta_r: str) -> str:
    return (
        f"eta_r=/joint_states:{eta_r},eta_l=/joint_states:velocity@left_wheel_joint,"
        "tau_r=/joint_states:effort@right_wheel_joint,tau_l=/joint_states:effort@left_wheel_joint"
    )


@pytest.fixture(scope="module")
def short_bags(tmp_path_factory) -> dict[str, Path]:
    """3 s of the sample as a ROS 1 bag (rosbags' dataclasses), a db3 folder and the MCAP file itself (mcap_ros2's
    namespaces): the two kinds of decoded message a field path walks."""
    folder = tmp_path_factory.mktemp("fieldpaths")
    messages = bagutil.recording(SAMPLE_MCAP)[:3000]
    return {
        "ros1": bagutil.write_ros1(folder / "short.bag", messages),
        "db3": bagutil.write_rosbag2(folder / "db3", messages),
        "mcap": bagutil.write_rosbag2(folder / "mcapdir", messages, "mcap") / "mcapdir.mcap",
    }


@pytest.mark.parametrize("kind", ["ros1", "db3", "mcap"])
@pytest.mark.parametrize(
    ("path", "why"),
    [
        ("__class__.__basicsize__", "no field '__class__' (its fields: header, name, position, velocity, effort)"),
        ("__msgtype__", "no field '__msgtype__'"),
        ("velocity.size", "/joint_states:velocity is an array, with no field 'size'"),
        ("velocity.__len__", "with no field '__len__'"),
        ("velocity", "/joint_states:velocity is an array (an element is [i] or @NAME), not a number"),
        ("header.stamp", "/joint_states:header.stamp is a message"),
        ("header.stamp.sec[0]", "/joint_states:header.stamp.sec is a number: it takes no [i] or @NAME"),
    ],
)
def test_a_field_path_reaches_no_python_attribute(short_bags, kind, path, why):
    """``__class__.__basicsize__`` was accepted (exit 0, m11 = -0.092) and ``velocity.size`` read numpy's attribute;
    now each is one line naming the path, the topic and the fields there are."""
    out = wmrid("identify", str(short_bags[kind]), "--columns", _columns(path), "--format", "json")
    line = assert_clean_error(out, 2, "wmrid:", f"/joint_states:{path}", why)
    assert "does not name a number of the messages on /joint_states" in line


def test_a_good_field_path_still_reads(short_bags):
    out = wmrid("identify", str(short_bags["db3"]), "--columns", _columns("velocity@right_wheel_joint"), "--format",
                "json")  # fmt: skip
    assert out.returncode in (0, 1), out.stderr
    assert b"Traceback" not in out.stderr


# ---------------------------------------------------------------------------------------------------------------
# Standard output on a full filesystem


def _run(*args: str, stdout=None, env_extra: dict[str, str] | None = None, preexec=None, timeout: float = 120):
    env = dict(os.environ, COLUMNS="100", **(env_extra or {}))
    return subprocess.run(
        [sys.executable, "-m", "wmrid", *args], stdout=stdout if stdout is not None else subprocess.PIPE,
        stderr=subprocess.PIPE, env=env, preexec_fn=preexec, timeout=timeout,
    )  # fmt: skip


@pytest.mark.parametrize("unbuffered", ["1", ""])
def test_a_short_write_to_standard_output_is_an_error_not_truncated_json(tmp_path, short_log, unbuffered):
    """A file on a filesystem with 16 KB left: the kernel takes the first 16 KB of the JSON, the next write fails.
    Under ``PYTHONUNBUFFERED=1`` Python dropped the rest of a short write silently (exit 0, truncated JSON); now
    every byte is written or the run ends 1 with one line.  The file-size limit (RLIMIT_FSIZE) stands in for the
    full filesystem: the same short write, then EFBIG instead of ENOSPC."""
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384))

    target = tmp_path / "out.json"
    with open(target, "wb") as fh:
        out = _run("identify", str(short_log), "--robot", "paper", "--format", "json", stdout=fh,
                   env_extra={"PYTHONUNBUFFERED": unbuffered}, preexec=limit)  # fmt: skip
    err = out.stderr.decode()
    assert out.returncode == 1, err
    assert err.splitlines() == [err.strip()]
    assert err.startswith("wmrid: ")
    assert "cannot write standard output" in err
    assert "incomplete" in err
    assert target.stat().st_size == 16384


def test_dev_full_as_standard_output_is_one_line_and_a_closed_pipe_stays_quiet(short_log):
    with open("/dev/full", "wb") as full:
        out = _run("identify", str(short_log), "--robot", "paper", stdout=full, env_extra={"PYTHONUNBUFFERED": "1"})
    err = out.stderr.decode()
    assert out.returncode == 1, err
    assert err.count("\n") == 1, err
    assert "No space left on device" in err
    # | head -c 10: the reader has seen enough, exit 0 and nothing on stderr
    proc = subprocess.Popen(
        [sys.executable, "-m", "wmrid", "identify", str(short_log), "--robot", "paper", "--format", "json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )  # fmt: skip
    head = proc.stdout.read(10)
    proc.stdout.close()
    assert proc.wait(timeout=120) == 0
    assert head == b'{\n  "schem'
    with proc.stderr:
        assert proc.stderr.read() == b""


# ---------------------------------------------------------------------------------------------------------------
# A signal while identify writes its two outputs


@pytest.fixture(scope="module")
def short_log(tmp_path_factory) -> Path:
    """A 4 s simulated log (CSV): what the processes below identify (its JSON result is 170 kB, past the 16 kB of
    the short write; the bundled 40 s sample cost each process half a second more)."""
    path = tmp_path_factory.mktemp("short") / "s.csv"
    assert wmrid("simulate", "--duration", "4", "-o", str(path)).returncode == 0
    return path


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGHUP"])
def test_a_signal_between_the_two_outputs_leaves_neither(tmp_path, short_log, signame):
    """``identify -o r.json --mcap-out est.mcap``, the signal sent the moment the estimates' temporary file appears
    (r.json is complete then; before issue 30 it stood alone afterwards).  Now both are committed together at the
    end: the stop leaves neither, no temporary file, and the line says so."""
    folder = tmp_path / "out"
    folder.mkdir()
    proc = subprocess.Popen(
        [sys.executable, "-m", "wmrid", "identify", str(short_log), "-o", str(folder / "r.json"), "--mcap-out",
         str(folder / "est.mcap")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    signalled = False
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        if any(n.startswith(".est.mcap.") for n in os.listdir(folder)):
            proc.send_signal(getattr(signal, signame))
            signalled = True
            break
    out, err = proc.communicate(timeout=120)
    if not signalled:  # the run outpaced the poll: then it must have written both outputs, whole
        assert proc.returncode == 0, err
        assert sorted(os.listdir(folder)) == ["est.mcap", "r.json"]
        return
    number = getattr(signal, signame)
    assert proc.returncode == 128 + number, err
    assert err.decode() == f"wmrid: terminated by {signame}; no output was written\n"
    assert os.listdir(folder) == []
    assert out == b""


def test_both_outputs_appear_when_the_run_ends(tmp_path, short_log):
    out = wmrid("identify", str(short_log), "-o", str(tmp_path / "r.json"), "--mcap-out", str(tmp_path / "e.mcap"))
    assert out.returncode == 0, out.stderr
    assert sorted(os.listdir(tmp_path)) == ["e.mcap", "r.json"]


# ---------------------------------------------------------------------------------------------------------------
# Markdown reports escape what came from an input

HOSTILE = "x<script>alert(1)</script> <img src=x onerror=alert(2)> <!-- c\n# heading\n| a | b |\n[l](javascript:x) `t`"


def _assert_inert(md: str, *needles: str) -> None:
    """No raw HTML from the input, no line that the input began; the input's words are still there, escaped."""
    for raw in ("<script", "<img", "<!--", "[l](javascript"):
        assert raw not in md, raw
    for line in md.splitlines():  # every line the input could have begun, by the words it holds
        assert not re.match(r"#+ (heading|owned|x|a note)", line), line
        assert not line.startswith("| a | b |"), line
    for needle in needles:
        assert needle in md, needle


def test_a_saved_results_source_notes_and_warnings_are_escaped_in_markdown(tmp_path, short_log):
    saved = tmp_path / "r.json"
    assert wmrid("identify", str(short_log), "--no-history", "-o", str(saved)).returncode == 0
    data = json.loads(saved.read_text())
    data["source"] = HOSTILE
    data["warnings"] = ["warning " + HOSTILE]
    data["log"]["notes"] = ["note " + HOSTILE, "# a note that is a heading"]
    saved.write_text(json.dumps(data))
    before = saved.read_bytes()
    out = wmrid("report", str(saved), "-o", str(tmp_path / "r.md"))
    assert out.returncode == 0, out.stderr
    md = (tmp_path / "r.md").read_text()
    _assert_inert(md, "x&lt;script&gt;alert(1)&lt;/script&gt;", "&lt;!-- c # heading \\| a \\| b \\|")
    assert saved.read_bytes() == before  # the input is never modified


def test_a_log_file_name_is_escaped_in_markdown(tmp_path, short_log):
    """The log's name reaches the title (the result's source), the result's name the provenance (command line,
    inputs)."""
    name = tmp_path / "run<img src=x onerror=alert(1)><!--\n# x `y` |z|.csv"
    shutil.copy(short_log, name)
    saved = name.with_suffix(".json")
    assert wmrid("identify", str(name), "--no-history", "-o", str(saved)).returncode == 0
    out = wmrid("report", str(saved), "-o", str(tmp_path / "r.md"))
    assert out.returncode == 0, out.stderr
    md = (tmp_path / "r.md").read_text()
    _assert_inert(md, "run&lt;img src=x onerror=alert(1)&gt;&lt;!-- # x")
    assert "- input <code>" in md  # not a backtick code span: the name holds a backtick and markup


def test_a_plans_robot_name_and_warnings_are_escaped_in_markdown(tmp_path):
    plan = ROOT / "tests" / "data" / "plan_hostile_names.json"
    out = wmrid("report", str(plan), "-o", str(tmp_path / "p.md"))
    assert out.returncode == 0, out.stderr
    md = (tmp_path / "p.md").read_text()
    _assert_inert(md, "# wmrid plan: amr&lt;script&gt;alert(1)&lt;/script&gt; # owned &lt;!-- x")
    assert "- &lt;img src=x onerror=alert(2)&gt; # heading from a warning \\| a \\| b" in md


def test_a_fleet_tables_robot_ids_are_escaped_in_markdown(tmp_path):
    from tests.fleetutil import synthetic_rows
    from wmrid.fleets.report import fleet_report, write_fleet_report

    rows = synthetic_rows(3, 12)
    for r in rows:
        if r["robot_id"] == "R01":
            r["robot_id"] = "R01<script>x</script>\n# owned"
    rep = fleet_report(rows, robot="paper", figures=False)
    write_fleet_report(rep, tmp_path / "f.md")
    md = (tmp_path / "f.md").read_text()
    _assert_inert(md, "### R01&lt;script&gt;x&lt;/script&gt; # owned")


def test_markdown_escaping_rules():
    from wmrid.reporting import markdown as md

    assert md.text("a_b *c* [d](e) `f` |g| ~h~ \\") == "a\\_b \\*c\\* \\[d\\](e) \\`f\\` \\|g\\| \\~h\\~ \\\\"
    assert md.text("<!-- & -->") == "&lt;!-- &amp; --&gt;"
    assert md.text("one\ntwo\r\nthree\u2028four\x0cfive") == "one two  three four five"
    for start, escaped in (("# h", "\\# h"), ("- l", "\\- l"), ("+ l", "\\+ l"), ("12. n", "12\\. n"),
                           ("===", "\\===")):  # fmt: skip
        assert md.text(start) == escaped
        assert md.text(start, start=False) == start.replace("|", "\\|")
    assert md.code("plain run.csv") == "`plain run.csv`"
    assert md.code("a`b<c") == "<code>a\\`b&lt;c</code>"
    assert md.table(["a|b"], [["-1", "x\ny"]]) == "| a\\|b |\n|---|\n| -1 | x y |"


# ---------------------------------------------------------------------------------------------------------------
# MuJoCo's own warnings


def test_a_floor_friction_out_of_range_is_one_line_before_mujoco_runs(tmp_path):
    """``--floor-friction 1e308`` printed 4,006 of MuJoCo's ``WARNING:`` lines (and wrote MUJOCO_LOG.TXT into the
    working folder); now the option's range, (0, 100], is checked first."""
    pytest.importorskip("mujoco")
    for value in ("1e308", "100.0001"):
        out = wmrid("simulate", "--engine", "mujoco", "--floor-friction", value, "--duration", "0.5", "-o",
                    str(tmp_path / "s.csv"), cwd=tmp_path)  # fmt: skip
        assert_clean_error(out, 2, "wmrid:", "--floor-friction must be in (0, 100]")
    assert os.listdir(tmp_path) == []


def test_mujocos_warnings_become_part_of_one_error(tmp_path, monkeypatch, capfd):
    """A run MuJoCo cannot integrate (the range check bypassed to reach the engine): its warnings are counted, the
    first quoted in the one error; nothing printed by MuJoCo itself, no MUJOCO_LOG.TXT."""
    pytest.importorskip("mujoco")
    from wmrid.core.errors import UsageError
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.multibody import simulate_multibody
    from wmrid.sim.multibody_model import MultibodySettings

    monkeypatch.chdir(tmp_path)
    settings = MultibodySettings()
    object.__setattr__(settings, "floor_friction", 1e308)  # what the range check now refuses
    amr = BUILTIN_ROBOTS["amr"]
    with pytest.raises(UsageError, match=r"unstable while the robot settled .* \(MuJoCo: Nan, Inf or huge value"):
        simulate_multibody(amr.cad, amr.nominal, settings=settings, duration=0.5)
    captured = capfd.readouterr()
    assert "WARNING" not in captured.out + captured.err
    assert os.listdir(tmp_path) == []
    import mujoco

    assert mujoco.get_mju_user_warning() is None  # MuJoCo's handler put back


# ---------------------------------------------------------------------------------------------------------------
# fleet-report on forged dates


@pytest.mark.parametrize(
    ("first", "step", "year"),
    [("0002-12-28", -1, "0002"), ("0001-01-01", 1, "0001"), ("9999-12-01", 0, "9999")],
)
def test_forged_dates_draw_quietly(tmp_path, first, step, year):
    """Start times at the ends of the calendar (years 1 and 9999; once a warning on stderr, or an "internal error"):
    every robot is drawn against its logs' dates, and stderr says only what was written."""
    import datetime as dt

    from tests.fleetutil import synthetic_rows
    from wmrid.fleets.table import write_table

    start = dt.datetime.fromisoformat(first).replace(tzinfo=dt.timezone.utc)
    rows = [dict(r, start_time=start + dt.timedelta(days=step * i)) for i, r in enumerate(synthetic_rows(2, 3))]
    table = tmp_path / "t.parquet"
    write_table(rows, table)
    out = wmrid("fleet-report", str(table), "-o", str(tmp_path / "r.html"))
    assert out.returncode == 0, out.stderr
    assert out.stderr.decode().splitlines() == [f"wrote {tmp_path / 'r.html'}"]
    page = (tmp_path / "r.html").read_text()
    assert page.count("<svg") == 3  # the evidence and both robots
    assert re.search(rf">({year}-\d\d-\d\d|{year})<", page)  # a date tick of that year


# ---------------------------------------------------------------------------------------------------------------
# fleet: failures said on stderr; a manifest of missing logs answered without the cluster


def test_a_manifest_of_missing_logs_fails_fast_and_says_so_on_stderr(tmp_path):
    """10^4 rows naming logs that are not there (10^5 took 49 s, nothing on stderr, exit 1): each row's error is
    written at once, no cluster is started (the summary counts 0 workers; no time is asserted), and stderr has one line
    saying how many failed and the first error."""
    import pyarrow.parquet as pq

    manifest = tmp_path / "m.csv"
    manifest.write_text("log,robot_id\n" + "".join(f"R{i % 10}/missing_{i}.csv,R{i % 10}\n" for i in range(10_000)))
    out = wmrid("fleet", "--manifest", str(manifest), "-o", str(tmp_path / "t.parquet"), "--format", "json")
    assert out.returncode == 1
    lines = out.stderr.decode().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("wmrid: 10000 of 10000 logs failed (each one's error is in the table's error column)")
    assert "missing_0.csv: cannot be read (No such file or directory)" in lines[0]
    summary = json.loads(out.stdout)
    assert (summary["logs"], summary["failed"], summary["workers"]) == (10_000, 10_000, 0)
    assert (summary["run"], summary["identified"]) == (10_000, 0)  # was "identified": 10000 beside "failed": 10000
    table = pq.read_table(tmp_path / "t.parquet", columns=["log", "error"])
    assert table.num_rows == 10_000
    assert table.column("error").null_count == 0


# ---------------------------------------------------------------------------------------------------------------
# A read-only install run by a user without a home: private temporary folders


@pytest.mark.parametrize("squatted", ["symlink", "world-writable", "file", None])
def test_the_fallback_cache_folder_is_private(tmp_path, monkeypatch, squatted):
    """numba's fallback cache lived in ``$TMPDIR/wmrid-numba-cache-UID`` whoever made it: a folder another user made
    first gave "internal error: cannot cache function" (and its pickles would have been loaded).  Now a folder that
    is not this user's own private folder is passed over for a fresh one."""
    import stat as st
    import tempfile

    import wmrid

    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)  # tempfile reads TMPDIR again
    usual = tmp_path / f"wmrid-test-{os.getuid()}"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    if squatted == "symlink":
        usual.symlink_to(elsewhere)
    elif squatted == "world-writable":
        usual.mkdir()
        usual.chmod(0o777)
    elif squatted == "file":
        usual.write_text("x")
    folder = Path(wmrid._private_temp_folder("wmrid-test"))
    info = folder.lstat()
    assert st.S_ISDIR(info.st_mode)
    assert info.st_mode & 0o077 == 0
    assert folder.parent == tmp_path
    assert (folder == usual) == (squatted is None)


@pytest.mark.parametrize(
    "entry",
    ["from wmrid.cli import main; main(['--version'])", "import runpy; runpy.run_module('wmrid', run_name='__main__')"],
)
@pytest.mark.parametrize("module", ["typer", "wmrid.cli.sim_commands"])
def test_ctrl_c_while_the_cli_is_still_importing_is_one_line(entry, module):
    """Ctrl-C before the application has installed its handling (seen in CI on a loaded machine: the signal landed
    inside typer's import and the default handler printed a traceback): one line, exit 130.  The process sends
    SIGINT to itself the moment ``module`` starts importing (an import hook placed before wmrid is imported), so the
    stop falls there every time: typer (while the application is imported) and a command's module (while the
    application gathers its commands; found by sending SIGINT 0.2-0.35 s into `wmrid identify`: 4 of 60 runs printed
    a traceback and died of the signal); both entry points, the console script's ``main`` and ``python -m wmrid``."""
    hook = (
        "import os, signal, sys\n"
        "class Stop:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        f"        if name == {module!r}:\n"
        "            os.kill(os.getpid(), signal.SIGINT)\n"
        "        return None\n"
        "sys.meta_path.insert(0, Stop())\n"
    )
    proc = subprocess.run([sys.executable, "-c", hook + entry], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr == "wmrid: interrupted; no output was written\n"
