"""Files the user did not name, read with care (issue 30, "hangs and unbounded memory"): a rosbag2 folder's
``metadata.yaml`` that is a link to ``/dev/zero``, a FIFO, or oversized; a FIFO named as a ``.db3``'s ``-wal`` or
``-shm``; a fleet manifest naming devices or files outside its folder; a glob over a folder with symbolic-link loops.

Every case is the real thing (a real link to a real device, a real FIFO, a real loop) run as a real process under a
timeout, so that a regression fails instead of hanging the suite; where memory is the point the process's peak
resident size is measured (by a small launcher process: ``RUSAGE_CHILDREN`` of a process that ran only it).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest
from locations import ROOT_DIR

from tests.cliutil import COLUMNS
from wmrid.core.errors import UsageError

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.mcap"
#: The budget the child processes run under, and the peak resident size they must stay below.
BUDGET = 256 << 20


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str
    peak_rss: int  # bytes

    def one_error(self, code: int, *needles: str) -> str:
        """The run failed with exit ``code``, one stderr line starting ``wmrid:`` holding every needle; that line."""
        assert self.returncode == code, self.stderr
        assert "Traceback" not in self.stderr
        lines = self.stderr.strip().splitlines()
        assert len(lines) == 1, self.stderr
        assert lines[0].startswith("wmrid:"), lines[0]
        for needle in needles:
            assert needle in lines[0], (needle, lines[0])
        return lines[0]


def run(
    *args: str,
    timeout: float = 20,
    cwd: Path | None = None,
    budget: str | None = str(BUDGET),
    cap: int | None = None,
    stdin=subprocess.DEVNULL,
) -> Run:
    """``python -m wmrid ARGS`` under WMRID_MEMORY_BUDGET=``budget`` (None: unset) and an address-space cap of
    ``cap`` bytes (RLIMIT_AS, as ``ulimit -v``), killed (and the test failed) past ``timeout`` seconds; its exit
    code, output and peak resident size."""
    env = dict(os.environ, COLUMNS=COLUMNS)
    env.pop("WMRID_MEMORY_BUDGET", None)
    if budget is not None:
        env["WMRID_MEMORY_BUDGET"] = budget

    def capped() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    with tempfile.TemporaryDirectory() as scratch:
        out, err, peak = (os.path.join(scratch, n) for n in ("out", "err", "peak"))
        with open(out, "wb") as out_fh, open(err, "wb") as err_fh:
            proc = subprocess.Popen(
                [sys.executable, "-c", _LAUNCHER, peak, sys.executable, "-m", "wmrid", *args], stdin=stdin,
                stdout=out_fh, stderr=err_fh, cwd=cwd, env=env, preexec_fn=capped if cap is not None else None,
                start_new_session=True,
            )  # fmt: skip
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                pytest.fail(f"wmrid {' '.join(args)} still running after {timeout} s (a hang)")
        with open(peak) as fh:
            peak_rss = int(fh.read()) * 1024
        return Run(proc.returncode, Path(out).read_text(), Path(err).read_text(), peak_rss)


#: A small process that runs the command and writes its peak resident size (KiB) to argv[1]: measured from the
#: test process itself, a child's ru_maxrss would start at the size of the (large) process it was forked from.
_LAUNCHER = """
import resource, subprocess, sys
code = subprocess.call(sys.argv[2:])
with open(sys.argv[1], "w") as fh:
    fh.write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss))
sys.exit(code if code >= 0 else 128 - code)
"""


# ---------------------------------------------------------------------------------------------------------------
# A rosbag2 folder's metadata.yaml


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
@pytest.mark.parametrize("command", ["identify", "inspect"])
def test_a_metadata_yaml_linked_to_an_endless_device_is_refused_unread(tmp_path, device, command):
    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "metadata.yaml").symlink_to(device)
    done = run(command, str(folder))
    done.one_error(2, f"{folder}/metadata.yaml", "a character device, not a regular file")
    assert done.peak_rss < BUDGET, done.peak_rss  # was 5.35 GB read whole by rosbags


def test_a_metadata_yaml_that_is_a_fifo_or_oversized_is_refused(tmp_path):
    fifo_folder, big_folder = tmp_path / "fifo", tmp_path / "big"
    fifo_folder.mkdir()
    big_folder.mkdir()
    os.mkfifo(fifo_folder / "metadata.yaml")  # no writer ever comes: a reader that opens it waits forever
    (big_folder / "metadata.yaml").write_bytes(b"#" * (5 << 20))
    run("inspect", str(fifo_folder)).one_error(2, "metadata.yaml", "a FIFO")
    run("inspect", str(big_folder)).one_error(2, "metadata.yaml", "over 4 MiB")


# ---------------------------------------------------------------------------------------------------------------
# A .db3's write-ahead log and shared-memory index: files beside it the user never named


@pytest.fixture(scope="module")
def small_db3(tmp_path_factory) -> Path:
    """A rosbag2 sqlite3 recording of the sample's first 6 s, written by rosbags."""
    from tests import bagutil

    messages = bagutil.recording(SAMPLE)
    first = messages[0].log_ns
    folder = bagutil.write_rosbag2(
        tmp_path_factory.mktemp("db3") / "rec", [m for m in messages if m.log_ns - first < 6e9]
    )
    return next(folder.glob("*.db3"))


@pytest.mark.parametrize("command", ["identify", "inspect"])
def test_a_fifo_named_as_the_write_ahead_log_is_ignored_never_opened(tmp_path, small_db3, command):
    db = tmp_path / "RUN.db3"
    db.write_bytes(small_db3.read_bytes())
    os.mkfifo(tmp_path / "RUN.db3-wal")  # no writer ever comes: opening it to read would wait forever
    os.mkfifo(tmp_path / "RUN.db3-shm")
    done = run(command, str(db))
    assert done.returncode == 0, done.stderr
    assert "(RUN.db3-wal) is a FIFO (named pipe), not a regular file: ignored, never opened" in done.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["RUN.db3", "RUN.db3-shm", "RUN.db3-wal"]


def test_a_device_named_as_the_write_ahead_log_in_a_rosbag2_folder_is_ignored(tmp_path, small_db3):
    folder = tmp_path / "rec"
    folder.mkdir()
    for f in small_db3.parent.iterdir():
        (folder / f.name).write_bytes(f.read_bytes())
    (folder / f"{small_db3.name}-wal").symlink_to("/dev/zero")
    done = run("inspect", str(folder))
    assert done.returncode == 0, done.stderr
    assert "is a character device, not a regular file: ignored, never opened" in done.stdout
    assert done.peak_rss < BUDGET, done.peak_rss


# ---------------------------------------------------------------------------------------------------------------
# A rosbag2 folder's storage files: named by its metadata.yaml, not by the user


def _raised(function, *args, timeout: float = 10) -> BaseException | None:
    """The exception function(*args) raised (None: it returned), the test failed (not hung) past ``timeout``."""

    def call() -> BaseException | None:
        try:
            function(*args)
        except BaseException as err:  # what it was, for the test to look at
            return err
        return None

    return _in_thread(call, timeout=timeout)


@pytest.mark.parametrize(
    ("what", "needle"),
    [
        ("fifo", "{db}: it is a FIFO (named pipe), not a regular file, so wmrid does not open it"),  # was a hang
        ("device", "{db}: it is a character device, not a regular file, so wmrid does not open it"),
        ("loop", "{db}: it is a loop of symbolic links, not a regular file"),
        ("metadata loop", "{meta}: it is a loop of symbolic links, so wmrid does not read it"),  # was: read as a
        ("metadata to nothing", "{meta}: it is a symbolic link to gone.yaml, which does not exist"),  # folder of files
    ],
)
def test_a_rosbag2_folders_storage_file_that_is_not_a_file_is_refused_unopened(tmp_path, small_db3, what, needle):
    from wmrid.core.errors import LogFormatError
    from wmrid.io.logs import read_log

    folder = tmp_path / "rec"
    folder.mkdir()
    meta, db = folder / "metadata.yaml", folder / small_db3.name
    if what.startswith("metadata"):
        meta.symlink_to("metadata.yaml" if what == "metadata loop" else "gone.yaml")
        db.write_bytes(small_db3.read_bytes())
    else:
        meta.write_bytes((small_db3.parent / "metadata.yaml").read_bytes())
        if what == "fifo":
            os.mkfifo(db)  # no writer ever comes: opening it to read would wait forever
        else:
            db.symlink_to("/dev/zero" if what == "device" else db.name)
    err = _raised(read_log, folder)
    assert isinstance(err, LogFormatError), err
    assert needle.format(db=db, meta=meta) in str(err)
    assert sorted(p.name for p in folder.iterdir()) == sorted([meta.name, db.name])


@pytest.mark.parametrize(
    ("make", "kind"),
    [(os.mkfifo, "a FIFO (named pipe)"), (lambda p: p.symlink_to("/dev/zero"), "a character device"),
     (lambda p: p.symlink_to(p.name), "a loop of symbolic links")],
)  # fmt: skip
def test_a_followed_recording_folders_mcap_file_that_is_not_a_file_is_refused_unopened(tmp_path, make, kind):
    """``wmrid live FOLDER`` opens the folder's NAME_0.mcap, NAME_1.mcap, ... as they appear: a FIFO so named waited
    forever, a loop of links was an "internal error"; now each is one line before it is opened."""
    from wmrid.core.errors import LogFormatError
    from wmrid.io.live.sources import open_live

    make(tmp_path / "rec_0.mcap")
    source = open_live(str(tmp_path))
    err = _raised(source.poll, 0.01)
    assert isinstance(err, LogFormatError), err
    assert str(err).startswith(f"{tmp_path}/rec_0.mcap: it is {kind}, not a regular file, so wmrid does not open it")


# ---------------------------------------------------------------------------------------------------------------
# A fleet manifest's logs


def _manifest(folder: Path, *rows: str) -> Path:
    path = folder / "m.csv"
    path.write_text("log\n" + "".join(f"{r}\n" for r in rows))
    return path


@pytest.mark.parametrize(
    ("row", "needles"),
    [
        ("/dev/zero", ["/dev/zero: resolves to /dev/zero, outside the manifest's folder", "--manifest-root"]),
        ("/etc/shadow", ["/etc/shadow: resolves to /etc/shadow, outside the manifest's folder"]),
        ("../../../../../../../../etc/passwd", ["resolves to /etc/passwd, outside the manifest's folder"]),
        ("link.csv", ["link.csv: resolves to /dev/zero, outside"]),  # a link out of the folder
        ("pipe.csv", ["pipe.csv is a FIFO (named pipe), not a log"]),
    ],
)
def test_a_manifest_reaches_only_logs_under_its_root(tmp_path, row, needles):
    (tmp_path / "link.csv").symlink_to("/dev/zero")
    os.mkfifo(tmp_path / "pipe.csv")
    done = run("fleet", "--manifest", str(_manifest(tmp_path, "ok.csv", row)), "-o", str(tmp_path / "t.parquet"))
    done.one_error(2, "m.csv row 3: ", *needles)
    assert not (tmp_path / "t.parquet").exists()  # refused before a worker started: nothing hashed, nothing written


def test_manifest_root_widens_the_rule_but_never_to_devices(tmp_path):
    from wmrid.fleets import manifest as fm

    inside = tmp_path / "fleet"
    inside.mkdir()
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "R1_2026-01-01.csv").write_text("t\n")
    (inside / "via_link").symlink_to(tmp_path / "logs")
    manifest = _manifest(inside, "../logs/R1_2026-01-01.csv", "via_link/R1_2026-01-01.csv")
    with pytest.raises(UsageError, match="outside the manifest's folder"):
        fm.read_manifest(manifest)
    a, b = fm.read_manifest(manifest, root=tmp_path)
    assert a.log == b.log == str((tmp_path / "logs" / "R1_2026-01-01.csv").resolve())  # the real path, in the table
    with pytest.raises(UsageError, match="is a character device, not a log"):
        fm.read_manifest(_manifest(inside, "/dev/zero"), root="/")
    (inside / "loop.csv").symlink_to("loop.csv")  # was a row failing as "No such file or directory"
    with pytest.raises(UsageError, match=r"row 2: loop.csv: .*/loop.csv is a loop of symbolic links, not a log"):
        fm.read_manifest(_manifest(inside, "loop.csv"))
    # the robot cells too: a FIFO there hung the worker that loaded it, /etc/shadow was read as TOML
    os.mkfifo(inside / "robot.toml")
    (inside / "R1_2026-01-01.csv").write_text("t\n")
    robots = inside / "robots.csv"
    for cell, needle in [
        ("robot.toml", "row 2: robot robot.toml: .*/robot.toml is a FIFO \\(named pipe\\), not a robot file"),
        ("/etc/shadow", "row 2: robot /etc/shadow: resolves to /etc/shadow, outside manifest_root "),
        ("../logs", "row 2: robot ../logs: .*/logs is a folder, not a robot file"),
    ]:
        robots.write_text(f"log,robot\nR1_2026-01-01.csv,{cell}\n")
        with pytest.raises(UsageError, match=needle):
            fm.read_manifest(robots, root=tmp_path)
    robots.write_text("log,robot\nR1_2026-01-01.csv,paper\nR1_2026-01-01.csv,via_link/../fleet/m.csv\n")
    paper, linked = fm.read_manifest(robots, root=tmp_path)
    assert (paper.robot, linked.robot) == ("paper", str((inside / "m.csv").resolve()))  # a name; a real path
    done = run("fleet", "--manifest", str(_manifest(inside, "/dev/zero")), "--manifest-root", "/", "-o", "t.parquet")
    done.one_error(2, "row 2: /dev/zero: /dev/zero is a character device, not a log")


def _in_thread(function, *args, timeout: float = 10):
    """function(*args) in a daemon thread, the test failed (not hung) when it has not returned after ``timeout``."""
    import threading

    out: list = []
    worker = threading.Thread(target=lambda: out.append(function(*args)), daemon=True)
    worker.start()
    worker.join(timeout)
    assert not worker.is_alive(), f"{function.__name__}{args} still running after {timeout} s (a hang)"
    return out[0]


def test_a_worker_hashes_a_log_boundedly_and_never_a_device_or_fifo(tmp_path):
    from wmrid.fleets.table import content_digest
    from wmrid.fleets.worker import identify_entry

    os.mkfifo(tmp_path / "pipe.csv")
    spec = {"robot_id": "R1", "options": {}, "options_key": "k", "fit": False, "known_sha256": None}
    for log, kind in (("/dev/zero", "a character device"), (str(tmp_path / "pipe.csv"), "a FIFO")):
        row = _in_thread(identify_entry, {**spec, "log": log})
        assert (
            row["error"] == f"{log}: cannot be read (it is {kind}{' (named pipe)' * (kind == 'a FIFO')}, not a "
            "regular file)"
        )
        assert row["sha256"] is None
    (tmp_path / "a.csv").write_bytes(b"x" * 3_000_000)
    import hashlib

    assert _in_thread(content_digest, str(tmp_path / "a.csv")) == (hashlib.sha256(b"x" * 3_000_000).hexdigest(),
                                                                    3_000_000)  # fmt: skip


# ---------------------------------------------------------------------------------------------------------------
# A recursive glob over symbolic-link loops


def _looped_tree(root: Path) -> Path:
    """L/R1/2026-01-01.csv and L/R2/2026-01-02.csv, with L/a and L/b links to L itself and L/R1/up a link to L."""
    top = root / "L"
    for robot, day in (("R1", "2026-01-01"), ("R2", "2026-01-02")):
        (top / robot).mkdir(parents=True)
        (top / robot / f"{day}.csv").write_text("t\n")
    (top / "a").symlink_to(".")
    (top / "b").symlink_to(".")
    (top / "R1" / "up").symlink_to("..")
    (top / "R2" / "zero.csv").symlink_to("/dev/zero")  # a glob result that is a device: not a log
    return top


def test_a_recursive_glob_follows_no_symlink_loop(tmp_path):
    import glob

    from wmrid.fleets.table import find_logs, safe_glob

    top = _looped_tree(tmp_path)
    found = _in_thread(find_logs, [f"{top}/**/2026*.csv"], timeout=5)
    assert found == [str(top / "R1" / "2026-01-01.csv"), str(top / "R2" / "2026-01-02.csv")]
    assert _in_thread(find_logs, [f"{top}/**/*.csv"], timeout=5) == found  # zero.csv (/dev/zero) is no log
    # without loops, the same matches as glob's own
    plain = tmp_path / "plain"
    for sub in ("x/y", "x/.hidden", "z"):
        (plain / sub).mkdir(parents=True)
        (plain / sub / "2026-01-01.csv").write_text("t\n")
    for pattern in ("**/*.csv", "**", "**/", "x/**/*.csv", "*/**/2026*", "**/y/*.csv"):
        want = sorted(glob.glob(f"{plain}/{pattern}", recursive=True))
        assert sorted(safe_glob(f"{plain}/{pattern}")) == want, pattern
    with pytest.raises(UsageError, match="walks more than"):
        safe_glob(f"{plain}/**/*.csv", limit=2)


def test_fleet_over_a_looped_tree_ends(tmp_path):
    top = _looped_tree(tmp_path)
    done = run("fleet", f"{top}/**/2027*.csv", "-o", str(tmp_path / "t.parquet"), timeout=10)
    done.one_error(2, "2027*.csv: the pattern matches no log")  # was: never ends (glob following L/a and L/b)


# ---------------------------------------------------------------------------------------------------------------
# Endless sources under an address-space cap

#: bytes: the address-space cap of these runs (``ulimit -v``); the default budget is then half of it.
CAP = 2_000_000_000


@pytest.mark.parametrize("how", ["log", "stdin", "model"])
def test_an_endless_source_under_a_cap_stops_at_a_budget_that_fits_it(tmp_path, how):
    """Under ``ulimit -v`` below the default budget, /dev/zero (as the log, or ``yes |`` as standard input, or
    monitor's --model) grew until a MemoryError, reported as "internal error"; the budget now fits the cap (half
    of it) and the read stops there with the usual line naming the input and the budget."""
    sample = str(ROOT / "sample_logs" / "paper_sinusoid.csv")
    if how == "stdin":
        yes = subprocess.Popen(["yes"], stdout=subprocess.PIPE)
        try:
            done = run("identify", "-", budget=None, cap=CAP, stdin=yes.stdout)
        finally:
            yes.kill()
            yes.wait()
            yes.stdout.close()
        done.one_error(2, "standard input holds more than 954 MiB, the memory budget (WMRID_MEMORY_BUDGET)")
    elif how == "log":
        done = run("identify", "/dev/zero", budget=None, cap=CAP)
        done.one_error(2, "/dev/zero: it is not a regular file and holds more than 954 MiB, the memory budget")
    else:
        done = run("monitor", "--model", "/dev/zero", sample, budget=None, cap=CAP)
        done.one_error(2, "--model /dev/zero: holds more than 954 MiB (WMRID_MEMORY_BUDGET)")
    assert "internal error" not in done.stderr
    assert done.peak_rss < CAP, done.peak_rss


def test_a_memory_error_is_one_line_naming_the_input_and_the_budget(tmp_path):
    """A budget set above the cap (the user's choice): the read fails with MemoryError before the budget, and the
    line says so, naming the input, the budget and the cap (was "internal error: MemoryError")."""
    done = run("identify", "/dev/zero", budget="4G", cap=1_500_000_000)
    line = done.one_error(2, "out of memory reading /dev/zero; the memory budget is 4 GiB (WMRID_MEMORY_BUDGET)")
    assert "under an address-space cap of 1.4 GiB (ulimit -v)" in line
