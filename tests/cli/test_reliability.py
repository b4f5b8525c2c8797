"""Reliability (issue 13): outputs that never clobber a device, a FIFO or an input; write errors that name their
target; SIGTERM and SIGHUP handled like Ctrl-C; a read-only install without a home folder.

Device targets are stand-ins made with mknod in a temporary folder (never the real /dev); a test that cannot make
one (no CAP_MKNOD) says so and does not run.  Signals, closed streams and the read-only install run the real
command in a subprocess; the rest call the CLI in-process.
"""

from __future__ import annotations

import os
import shutil
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from locations import ROOT_DIR

from wmrid.cli.app import main

ROOT = ROOT_DIR


def run(*argv: str) -> int:
    with pytest.raises(SystemExit) as info:
        main(list(argv))
    return int(info.value.code)


@pytest.fixture(scope="module")
def small_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("log") / "in.csv"
    assert run("simulate", "--duration", "2", "-o", str(path)) == 0
    return path


def _device(folder: Path, name: str, kind: int, major: int, minor: int) -> Path:
    path = folder / name
    try:
        os.mknod(path, kind | 0o666, os.makedev(major, minor))
    except PermissionError:
        pytest.skip("making a device stand-in needs CAP_MKNOD, which this machine does not give")
    return path


def test_a_character_device_is_written_in_place_never_replaced(tmp_path, small_log, capsys):
    """``-o NULL --force``, NULL a stand-in of /dev/null: exit 0, and it is still the same character device (before
    issue 13 it became a regular file: as root, ``-o /dev/null --force`` broke /dev/null for the whole system)."""
    null = _device(tmp_path, "null", stat.S_IFCHR, 1, 3)
    before = os.stat(null)
    assert run("identify", str(small_log), "-o", str(null), "--force", "--format", "json") == 0
    after = os.stat(null)
    assert stat.S_ISCHR(after.st_mode)
    assert (after.st_ino, after.st_rdev) == (before.st_ino, before.st_rdev)
    assert run("identify", str(small_log), "-o", str(null), "--format", "json") == 0  # no --force needed
    capsys.readouterr()


def test_a_full_device_is_a_one_line_write_error(tmp_path, small_log, capsys):
    """``-o FULL``, FULL a stand-in of /dev/full (every write fails with ENOSPC): exit 1 and one line naming it."""
    full = _device(tmp_path, "full", stat.S_IFCHR, 1, 7)
    assert run("identify", str(small_log), "-o", str(full), "--format", "json") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert str(full) in err[0]
    assert "No space left on device" in err[0]
    assert stat.S_ISCHR(os.stat(full).st_mode)


def test_a_block_device_is_refused(tmp_path, small_log, capsys):
    """A block device (a stand-in whose numbers name no device) is never opened: exit 2, one line."""
    block = _device(tmp_path, "disk", stat.S_IFBLK, 250, 250)
    assert run("identify", str(small_log), "-o", str(block), "--force", "--format", "json") == 2
    assert "block device" in capsys.readouterr().err
    assert stat.S_ISBLK(os.stat(block).st_mode)


def test_a_fifo_is_written_in_place(tmp_path, small_log, capsys):
    """``-o FIFO``: the reader at the other end gets the whole result, and the FIFO stays a FIFO."""
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()))
    reader.start()
    assert run("identify", str(small_log), "-o", str(fifo), "--format", "json") == 0
    reader.join(timeout=60)
    assert received
    assert received[0].startswith(b"{")
    assert received[0].rstrip().endswith(b"}")
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    capsys.readouterr()


@pytest.mark.parametrize("how", ["same path", "hard link", "symbolic link"])
def test_an_output_that_is_the_input_is_refused(tmp_path, small_log, capsys, how):
    """``identify in.csv -o in.csv --force`` overwrote the log with the result; now exit 2, one line naming the
    input, the log byte for byte as it was, whichever name the output gives it."""
    log = tmp_path / "in.csv"
    shutil.copy(small_log, log)
    original = log.read_bytes()
    target = {"same path": log, "hard link": tmp_path / "hard.csv", "symbolic link": tmp_path / "soft.csv"}[how]
    if how == "hard link":
        os.link(log, target)
    elif how == "symbolic link":
        target.symlink_to(log)
    assert run("identify", str(log), "-o", str(target), "--force", "--format", "json") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "it is the input" in err[0]
    assert log.read_bytes() == original


def test_a_symbolic_link_output_writes_the_file_it_names(tmp_path, small_log, capsys):
    """A link as ``-o``: the file it points to gets the result; the link stays a link."""
    link = tmp_path / "result.json"
    link.symlink_to("real.json")
    assert run("identify", str(small_log), "-o", str(link), "--format", "json") == 0
    assert link.is_symlink()
    assert (tmp_path / "real.json").read_text().startswith("{")
    capsys.readouterr()


def test_a_long_output_name_is_written(tmp_path, small_log, capsys):
    """A legal 250-character name failed because the temporary name was longer than NAME_MAX."""
    target = tmp_path / ("r" * 245 + ".json")
    assert run("identify", str(small_log), "-o", str(target), "--format", "json") == 0
    assert target.read_text().startswith("{")
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]
    capsys.readouterr()


def _command(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "wmrid", *args], stdout=kwargs.pop("stdout", subprocess.PIPE),
        stderr=subprocess.PIPE, **kwargs,
    )  # fmt: skip


@pytest.mark.slow  # a real process per broken stream (5 s)
def test_standard_streams_that_fail(tmp_path, small_log):
    """Real processes: stdout on a full device, and stdout closed, exit 1 with one line naming standard output (was
    exit 0 with truncated JSON, and "internal error"); stderr closed does not turn a success into a failure."""
    full = _device(tmp_path, "full", stat.S_IFCHR, 1, 7)
    with open(full, "wb") as sink:
        proc = _command("identify", str(small_log), "--format", "json", stdout=sink)
        _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    assert err.decode().strip().splitlines() == [
        "wmrid: error: cannot write standard output: No space left on device; what was printed is incomplete"
    ]
    # closed before the program starts, as `>&-` does (closing it later would let the next file opened take fd 1)
    closed = subprocess.run(
        [sys.executable, "-m", "wmrid", "identify", str(small_log), "--format", "json"],
        stderr=subprocess.PIPE, preexec_fn=lambda: os.close(1), timeout=300,
    )  # fmt: skip
    assert closed.returncode == 1, closed.stderr
    assert b"cannot write standard output" in closed.stderr
    quiet = subprocess.run(
        [sys.executable, "-m", "wmrid", "identify", str(small_log), "--format", "table"],
        stdout=subprocess.PIPE, preexec_fn=lambda: os.close(2), timeout=300,
    )  # fmt: skip
    assert quiet.returncode == 0
    assert b"m11" in quiet.stdout


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_leave_no_temporary_file(tmp_path, signum):
    """``simulate`` stopped by SIGTERM (``timeout``, ``docker stop``) or SIGHUP (a closed terminal) while it writes
    its log: exit 128 + the signal, one line, no ``.tmp`` file and neither half of the log + truth group (both
    used to be left behind).  The signal is sent when the temporary file appears (or after 20 s)."""
    out = tmp_path / "run.csv"
    proc = _command("simulate", "--duration", "400", "-o", str(out), cwd=tmp_path)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and not any(p.name.endswith(".tmp") for p in tmp_path.iterdir()):
        time.sleep(0.005)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signum, err
    (line,) = err.decode().strip().splitlines()
    assert line.startswith(f"wmrid: terminated by {signal.Signals(signum).name}"), line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # installs a copy and compiles every kernel from nothing: 14 s
def test_a_read_only_install_without_a_home_folder(tmp_path, small_log):
    """Installed where nothing can be written and run by a user whose HOME does not exist, every command but --help
    failed with "cannot cache function" (numba's on-disk cache).  Made here without privileges: the package's
    ``__pycache__`` is a file and HOME lies under a file, so neither cache folder can be created, even by root.
    ``simulate`` and ``identify`` run, with numba's cache in a folder under TMPDIR."""
    site = tmp_path / "site"
    shutil.copytree(ROOT / "wmrid", site / "wmrid", ignore=shutil.ignore_patterns("__pycache__"))
    (site / "wmrid" / "__pycache__").write_text("not a folder")
    (tmp_path / "blocker").write_text("a file")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "PYTHONPATH")}
    env.update(HOME=str(tmp_path / "blocker" / "home"), TMPDIR=str(tmp), PYTHONDONTWRITEBYTECODE="1")
    code = f"import sys; sys.path.insert(0, {str(site)!r}); from wmrid.cli.app import main; main()"
    out = tmp_path / "sim.csv"
    for args in (["simulate", "--duration", "1", "-o", str(out)], ["identify", str(out), "--format", "json"]):
        proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, env=env, timeout=300)
        assert proc.returncode == 0, proc.stderr
    assert any(p.name.startswith("wmrid-numba-cache") for p in tmp.iterdir())


def test_a_simulation_beyond_the_memory_budget_is_a_usage_error(capsys, tmp_path):
    """``simulate --duration 1e9`` died of "MemoryError: Unable to allocate 14.6 TiB"; now exit 2 before anything is
    allocated, one line naming the budget and the longest run it allows (the output could be written: an output that
    cannot is refused first, before any import)."""
    out = tmp_path / "never.csv"
    assert run("simulate", "--duration", "1e9", "-o", str(out)) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "WMRID_MEMORY_BUDGET" in line
    assert "simulate at most" in line
    assert list(tmp_path.iterdir()) == []


def test_a_malformed_memory_budget_is_a_usage_error(monkeypatch, small_log, capsys):
    monkeypatch.setenv("WMRID_MEMORY_BUDGET", "lots")
    assert run("identify", str(small_log), "--format", "json") == 2
    assert "WMRID_MEMORY_BUDGET='lots'" in capsys.readouterr().err


def test_endless_sources_stop_at_the_budget(tmp_path, small_log, monkeypatch, capsys):
    """A stand-in of /dev/zero as the log, as the robot file, and as standard input: each read whole until a
    MemoryError before; now each stops at its limit (the 8 MiB budget set here; 16 MiB for a robot file) with one
    line and exit 2."""
    import io

    zero = _device(tmp_path, "zero", stat.S_IFCHR, 1, 5)
    monkeypatch.setenv("WMRID_MEMORY_BUDGET", "8M")
    assert run("identify", str(zero), "--format", "json") == 2
    assert "holds more than 8 MiB" in capsys.readouterr().err
    assert run("identify", str(small_log), "--robot", str(zero), "--format", "json") == 2
    assert "holds more than 16 MiB" in capsys.readouterr().err
    with open(zero, "rb") as endless:
        monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(endless))
        assert run("identify", "-", "--format", "json") == 2
    assert "standard input holds more than 8 MiB" in capsys.readouterr().err


def test_deeply_nested_files_are_one_line_errors(tmp_path, small_log, capsys):
    """A robot TOML or a saved result nested 100,000 deep: "internal error: RecursionError" before; now exit 2."""
    deep_toml = tmp_path / "deep.toml"
    deep_toml.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    assert run("identify", str(small_log), "--robot", str(deep_toml), "--format", "json") == 2
    assert "nested too deeply" in capsys.readouterr().err
    deep_json = tmp_path / "deep.json"
    deep_json.write_text('{"a":' * 100_000 + "1" + "}" * 100_000)
    assert run("report", str(deep_json)) == 2
    assert "nested too deeply" in capsys.readouterr().err


def test_a_large_parquet_row_group_is_read_in_slices(tmp_path, monkeypatch):
    """A row group too large to decode at once (2 MB of Parquet can hold 100 M rows of zeros in one) is read in
    slices: the same values as the whole-group read.  Forced here on a small file with a 1 KiB threshold; measured
    on 20 M rows in one group: 88 MB of Arrow memory at most, against 1.2 GB decoded whole."""
    import numpy as np

    import wmrid.io.logs
    from wmrid.io.logs import read_log, write_log
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.simulate import simulate

    robot = BUILTIN_ROBOTS["paper"]
    frame = simulate(robot.cad, robot.nominal, duration=3.0).to_frame()[["t", "eta_r", "eta_l", "tau_r", "tau_l"]]
    path = tmp_path / "one_group.parquet"
    write_log(frame, str(path))
    whole = read_log(str(path))
    monkeypatch.setattr(wmrid.io.table.parquet_log, "ROW_GROUP_SLICE_BYTES", 1024)
    sliced = read_log(str(path))
    np.testing.assert_array_equal(sliced.t, whole.t)
    np.testing.assert_array_equal(sliced.eta, whole.eta)
    np.testing.assert_array_equal(sliced.tau, whole.tau)


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "internal error" not in err[0]
    return err[0]


def test_messages_that_blamed_the_wrong_thing(tmp_path, small_log, capsys):
    """The red team's list: each is now one line, exit 2, naming what is wrong (in quotes: what it said before)."""
    dangling = tmp_path / "dangling.csv"
    dangling.symlink_to("nothere.csv")
    loop = tmp_path / "loop1.csv"
    loop.symlink_to("loop2.csv")
    (tmp_path / "loop2.csv").symlink_to("loop1.csv")
    cases = {
        # "no such file (did you mean '<the same path>'?)"
        ("identify", str(dangling)): "a symbolic link to 'nothere.csv', which does not exist",
        ("identify", str(loop)): "loops back on itself",
        # "does not excite the dynamics"
        ("identify", str(small_log), "--k", "1e308"): "--k must be a number in (0, 100000]",
        ("identify", str(small_log), "--columns", "t=t,eta_r=eta_r,eta_l=eta_r,tau_r=tau_r,tau_l=tau_l"): (
            "maps both eta_r and eta_l to the column 'eta_r'"
        ),
        # "below the minimum"
        ("identify", str(small_log), "--method", "rls", "--forgetting", "1.5"): "above 1 the recursion",
        # accepted
        ("identify", str(small_log), "--box-width", "nan"): "--box-width must be a number > 0",
        ("simulate", "--duration", "1", "--payload", "25@", "-o", str(tmp_path / "p.csv")): "expected MASS[@X,Y]",
    }
    for argv, needle in cases.items():
        code = run(*argv, "--format", "json") if argv[0] == "identify" else run(*argv)
        assert code == 2, argv
        assert needle in _one_error(capsys), argv


def test_formats_wmrid_does_not_read_are_named(tmp_path, small_log, capsys):
    """A zip archive or a ROS 1 bag was "byte 8 is a NUL byte"; now the format is named with the way out, or read.
    (Compressed CSV and bags are read: tests/unit/io/test_compressed.py, tests/unit/io/test_bags.py.)"""
    import zipfile

    with zipfile.ZipFile(tmp_path / "logs.zip", "w") as archive:
        archive.write(small_log, "in.csv")
    (tmp_path / "run.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(64))
    for name, needle in (("logs.zip", "a zip archive"), ("run.bag", "no sensor_msgs/msg/JointState messages found")):
        assert run("identify", str(tmp_path / name), "--format", "json") == 2
        assert needle in _one_error(capsys)


def test_broken_saved_results_and_parquet_files_are_named(tmp_path, small_log, capsys):
    """A saved result without ``log`` or with a malformed history, and a Parquet file with two columns of one name,
    were "internal error"s (and the report's errors named the file "?")."""
    import json

    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    result = tmp_path / "r.json"
    assert run("identify", str(small_log), "-o", str(result), "--format", "json") == 0
    capsys.readouterr()
    data = json.loads(result.read_text())
    no_log = {k: v for k, v in data.items() if k != "log"}
    (tmp_path / "nolog.json").write_text(json.dumps(no_log))
    (tmp_path / "badhist.json").write_text(json.dumps({**data, "history": {"t": [0, 1], "theta": "x"}}))
    for name in ("nolog.json", "badhist.json"):
        assert run("report", str(tmp_path / name)) == 2
        line = _one_error(capsys)
        assert name in line
        assert "not a complete identify result" in line
    columns = [pa.array(np.arange(100) * 1e-3)] * 2 + [pa.array(np.zeros(100))] * 4
    pq.write_table(pa.table(columns, names=["t", "t", "eta_r", "eta_l", "tau_r", "tau_l"]), tmp_path / "dup.parquet")
    assert run("identify", str(tmp_path / "dup.parquet"), "--format", "json") == 2
    assert "used twice ('t')" in _one_error(capsys)


def test_a_csv_header_of_millions_of_columns_is_refused_at_once(tmp_path, capsys):
    """A header of 10 M columns took 3.4 GB and 75 s; a first line beyond 1 MiB is now refused after reading 1 MiB."""
    wide = tmp_path / "wide.csv"
    with open(wide, "w") as fh:
        fh.write(",".join(f"column{i}" for i in range(300_000)) + "\n")
        fh.write(",".join("0" for _ in range(300_000)) + "\n")
    assert run("identify", str(wide), "--format", "json") == 2
    assert "first line is longer than 1 MiB" in _one_error(capsys)


def test_an_mcap_cut_mid_chunk_says_so(tmp_path, capsys):
    """An MCAP cut in its only chunk said "holds no channels", with no word of the truncation."""
    from wmrid.io.mcap.writer import write_joint_state_mcap
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.simulate import simulate

    robot = BUILTIN_ROBOTS["paper"]
    full = tmp_path / "full.mcap"
    write_joint_state_mcap(full, simulate(robot.cad, robot.nominal, duration=3.0).to_frame(), odom_topic=None)
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert run("identify", str(cut), "--format", "json") == 2
    assert "cut short" in _one_error(capsys)


STUCK = """
import sys
import numba
from wmrid.runtime import interrupts
from wmrid.runtime.atomic import atomic_output

interrupts.install()
interrupts.GRACE_S = 1.0
interrupts.start_watchdog()


@numba.njit(nogil=True)
def spin(n):
    s = 0
    for i in range(n):
        s += i % 7
    return s


spin(10)
with atomic_output(sys.argv[1]) as fh:
    fh.write(b"partial")
    print("ready", flush=True)
    spin(10**15)
"""


@pytest.mark.slow  # a real process and a signal
def test_a_signal_ends_a_process_stuck_in_compiled_code(tmp_path):
    """Python runs a signal handler only between bytecodes, so SIGTERM did not end a process inside a long compiled
    loop (``timeout`` waited forever).  The watchdog ends it GRACE_S later (1 s here): exit 143, its temporary file
    removed, one line saying why."""
    proc = subprocess.Popen(
        [sys.executable, "-c", STUCK, str(tmp_path / "out.bin")], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    assert proc.stdout.readline().strip() == b"ready"
    assert any(p.name.endswith(".tmp") for p in tmp_path.iterdir())
    time.sleep(0.5)  # into the compiled loop (a signal before it would be handled as usual)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert b"did not return to Python within 1 s" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # a real process on a small filesystem
def test_a_file_too_large_for_the_disk_is_one_line_and_leaves_nothing(tmp_path):
    """A write that fails midway (here RLIMIT_FSIZE, 20 kB: EFBIG, as a full disk gives ENOSPC): exit 1, one line
    naming the file, and neither the log, its truth file nor a temporary file is left."""
    import resource

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    proc = subprocess.run(
        [sys.executable, "-m", "wmrid", "simulate", "--duration", "5", "-o", "run.csv"], cwd=tmp_path,
        preexec_fn=small_files, capture_output=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.decode().strip().splitlines() == [
        "wmrid: error: cannot write run.csv: File too large; nothing was written there in full"
    ]
    assert list(tmp_path.iterdir()) == []


def test_a_signal_inside_held_waits_for_its_end():
    """A result group's renames run inside ``interrupts.held()``: a stopping signal handled there (as when it reaches
    another thread, which pthread_sigmask does not hold back) is raised only when the block ends."""
    from wmrid.runtime import interrupts

    done = []

    def group() -> None:
        with interrupts.held():
            interrupts._interrupt(signal.SIGTERM, None)
            done.append("renamed")

    with pytest.raises(interrupts.Terminated):
        group()
    assert done == ["renamed"]


def test_a_stop_dropped_in_a_weakref_callback_is_raised_again():
    """A SIGTERM whose handler runs inside a weakref callback (where Python drops the exception: "Exception ignored";
    seen in CI as the import system's module-lock callback, and ``wmrid simulate`` then wrote its log and exited 0) is
    raised again a moment later, in the code that runs next, and nothing is printed for the dropped one."""
    import gc
    import weakref

    from wmrid.runtime import interrupts

    class Thing:
        pass

    def callback(_):
        signal.raise_signal(signal.SIGTERM)  # the handler runs here, inside the callback

    previous = interrupts.install()
    try:
        hook = sys.unraisablehook
        thing = Thing()
        ref = weakref.ref(thing, callback)

        def drop_and_wait() -> None:
            nonlocal thing
            thing = None  # the callback runs; its Terminated is dropped, then raised again by the hook's timer
            gc.collect()
            time.sleep(2.0)

        with pytest.raises(interrupts.Terminated):
            drop_and_wait()
        assert ref() is None
        assert interrupts.received == signal.SIGTERM
    finally:
        interrupts.restore(previous)
    assert sys.unraisablehook is not hook  # restored to the caller's
    assert signal.getsignal(signal.SIGTERM) is previous[signal.SIGTERM]


def test_a_stop_dropped_at_the_end_still_ends_the_run_as_stopped(tmp_path, monkeypatch):
    """A stop dropped so late that the command returns before it is raised again: the command line still exits
    128 + the signal and says what it wrote (complete) before the stop, instead of exit 0."""
    from types import SimpleNamespace

    from wmrid.runtime import interrupts

    real_disarm = interrupts.disarm

    def dropped_just_now() -> bool:  # the command has returned: a SIGTERM arrives and is dropped in a callback
        interrupts.received = signal.SIGTERM
        interrupts._unraisable(SimpleNamespace(exc_value=interrupts.Terminated(signal.SIGTERM)))
        return real_disarm()

    monkeypatch.setattr(interrupts, "disarm", dropped_just_now)
    out = tmp_path / "run.csv"
    code = run("simulate", "--duration", "0.5", "-o", str(out))
    assert code == 128 + signal.SIGTERM
    assert out.exists()  # written in full before the stop, and said so


def test_a_stop_still_waiting_when_the_command_ends_is_owed():
    """Whatever kept a stop waiting when the command returned (a retry of a Ctrl-C deferred while numba compiled, a
    stop held back by a block that then raised) makes :func:`disarm` say a stop is owed; nothing else does."""
    from wmrid.runtime import interrupts

    previous = interrupts.install()
    try:
        assert interrupts.disarm() is False  # nothing received
        interrupts.received = signal.SIGINT
        signal.setitimer(signal.ITIMER_REAL, 5.0)  # the compile retry, still pending
        assert interrupts.disarm() is True
        assert signal.getitimer(signal.ITIMER_REAL)[0] == 0  # and cancelled
        interrupts.received = None

        def failing_block() -> None:
            with interrupts.held():
                interrupts._interrupt(signal.SIGTERM, None)  # held back...
                raise RuntimeError("the block fails")  # ...and never raised at the block's end

        with pytest.raises(RuntimeError):
            failing_block()
        assert interrupts.disarm() is True
    finally:
        interrupts.restore(previous)
    assert interrupts.install() is not None  # a fresh install forgets it
    try:
        assert interrupts.disarm() is False
    finally:
        interrupts.restore({})


def test_the_hook_never_calls_itself_through_a_wrapper_left_installed():
    """A hook that wrapped wmrid's and stayed installed after :func:`restore` is the previous hook of the next
    :func:`install`: an ordinary unraisable exception then went wrapper -> wmrid's -> wrapper ... (RecursionError)."""
    from wmrid.runtime import interrupts

    seen = []
    caller = sys.unraisablehook
    first = interrupts.install()
    ours = sys.unraisablehook

    def wrapper(info) -> None:
        seen.append(info)
        ours(info)

    sys.unraisablehook = wrapper
    interrupts.restore(first)
    second = interrupts.install()

    class Boom:
        def __del__(self) -> None:
            raise ValueError("dropped in __del__")  # an ordinary unraisable exception, not a stop

    try:
        Boom()  # collected at once: the hook chain runs (the default hook prints it to stderr)
    finally:
        interrupts.restore(second)
        sys.unraisablehook = caller
    assert len(seen) == 1  # wmrid's hook -> the wrapper (its previous) -> wmrid's again -> the default: no loop


def test_in_process_calls_keep_the_callers_streams(tmp_path, capsys):
    """``main([...])`` under a text-only stdout (StringIO) writes CSV there (it exited 1, "standard output is
    closed"), and with --debug an error leaves the caller's streams and SIGINT handler as they were."""
    import contextlib
    import io

    from wmrid.core.errors import LogFormatError

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        assert run("simulate", "--duration", "0.5", "-o", "-") == 0
    assert buffer.getvalue().startswith("t,eta_r")
    stdout, handler = sys.stdout, signal.getsignal(signal.SIGINT)
    with pytest.raises(LogFormatError):
        main(["--debug", "identify", str(tmp_path / "missing.csv")])
    assert sys.stdout is stdout
    assert signal.getsignal(signal.SIGINT) is handler
    capsys.readouterr()


def test_output_to_standard_output_is_one_json_document(small_log, capsys):
    """``identify LOG -o -`` printed the result twice (two JSON documents: not JSON)."""
    import json

    assert run("identify", str(small_log), "-o", "-") == 0
    json.loads(capsys.readouterr().out)


def test_a_long_name_in_bytes_is_written(tmp_path, small_log, capsys):
    """NAME_MAX counts bytes: 'ü' * 120 + '.json' is 245 bytes (legal); its temporary name is cut by bytes."""
    target = tmp_path / ("ü" * 120 + ".json")
    assert run("identify", str(small_log), "-o", str(target), "--format", "json") == 0
    assert target.exists()
    capsys.readouterr()


@pytest.mark.slow  # real processes under RLIMIT_AS
def test_under_an_address_space_cap_a_log_identifies_and_an_endless_source_stops(tmp_path, small_log):
    """Real processes under RLIMIT_AS = 2 GB (``ulimit -v``, ``prlimit --as``): a 2 s log identifies (a 3 s log hung
    inside OpenBLAS's eigvalsh: one buffer per thread), and a /dev/zero stand-in as the log stops at a 256 MiB
    budget with one line instead of growing until MemoryError."""
    import resource

    def capped() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (2_000_000_000, 2_000_000_000))

    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    proc = subprocess.run(
        [sys.executable, "-m", "wmrid", "identify", str(small_log), "--format", "json"], preexec_fn=capped,
        capture_output=True, timeout=180, env=env,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    zero = _device(tmp_path, "zero", stat.S_IFCHR, 1, 5)
    proc = subprocess.run(
        [sys.executable, "-m", "wmrid", "identify", str(zero), "--format", "json"], preexec_fn=capped,
        capture_output=True, timeout=180, env={**env, "WMRID_MEMORY_BUDGET": "256M"},
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert b"holds more than 256 MiB" in proc.stderr


def test_an_in_process_run_keeps_the_callers_alarm(small_log):
    """``main(argv)`` in a caller's process (a notebook, a test with an alarm-based timeout): the caller's
    SIGALRM handler and its pending timer come back, the timer with the time it had left (within the run's
    wall time), and it fires into the caller's handler, not wmrid's."""
    fired = []
    previous = signal.signal(signal.SIGALRM, lambda *_: fired.append(True))
    try:
        signal.setitimer(signal.ITIMER_REAL, 30.0)
        started = time.monotonic()
        with pytest.raises(SystemExit) as done:
            main(["identify", str(small_log), "--format", "json"])
        assert done.value.code == 0
        left, _ = signal.getitimer(signal.ITIMER_REAL)
        assert 30.0 - (time.monotonic() - started) - 0.5 < left <= 30.0
        signal.setitimer(signal.ITIMER_REAL, 0.01)
        time.sleep(0.2)
        assert fired == [True]
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
