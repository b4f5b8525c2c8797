"""``wmrid live`` (issue 32): logs followed while a writer thread (or a pipe) grows them, the observer fed in pieces,
and the final result, which must be ``wmrid.identify`` on the same messages.

The data: the first 5 s of the bundled paper-scenario log (1 kHz), written as CSV rows, as JointState messages with
mcap_ros2's writer (chunked, small zstd chunks) and with mcap's own writer unchunked, and as a rosbag2 folder split in
two MCAP files (rosbags' writer, then copied in piece by piece as a recorder would write it).
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from locations import ROOT_DIR

import wmrid
from tests.cliutil import COLUMNS

SAMPLE = ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"
N = 5000  # samples: 5 s at 1 kHz


@pytest.fixture(scope="module")
def log():
    whole = wmrid.read_log(str(SAMPLE))
    return whole.t[:N], whole.eta[:N], whole.tau[:N]


def csv_bytes(t, eta, tau) -> bytes:
    cols = zip(t.tolist(), eta[:, 0].tolist(), eta[:, 1].tolist(), tau[:, 0].tolist(), tau[:, 1].tolist(), strict=True)
    rows = [f"{a!r},{b!r},{c!r},{d!r},{e!r}\n" for a, b, c, d, e in cols]
    return ("t,eta_r,eta_l,tau_r,tau_l\n" + "".join(rows)).encode()


def same(live_result, offline, rel=1e-9):
    """The live run's final result is identify's: the estimate to ``rel``, the std and warnings as offline."""
    assert live_result.parameters.keys() == offline.parameters.keys()
    for name, (value, std) in offline.parameters.items():
        got, got_std = live_result.parameters[name]
        assert got == pytest.approx(value, rel=rel, abs=1e-15), name
        assert got_std == pytest.approx(std, rel=1e-6) or (np.isinf(std) and np.isinf(got_std)), name
    assert live_result.warnings == offline.warnings


def follow(source, **kwargs):
    """Run wmrid.live to its end: (the updates, the LiveResult)."""
    run = wmrid.live(str(source), "paper", every=0.2, **kwargs)
    items = list(run)
    assert isinstance(items[-1], wmrid.LiveResult)
    assert all(isinstance(u, wmrid.LiveUpdate) for u in items[:-1])
    return items[:-1], items[-1]


def grow(path: Path, data: bytes, pieces: int = 40, pause: float = 0.01) -> threading.Thread:
    """A thread appending ``data`` to ``path`` in ``pieces`` uneven pieces (cut anywhere: torn lines and records)."""
    rng = np.random.default_rng(7)
    cuts = np.sort(rng.choice(np.arange(1, len(data)), size=pieces - 1, replace=False))
    bounds = [0, *cuts.tolist(), len(data)]

    def write() -> None:
        with open(path, "ab") as fh:
            for a, b in itertools.pairwise(bounds):
                fh.write(data[a:b])
                fh.flush()
                time.sleep(pause)

    thread = threading.Thread(target=write, daemon=True)
    thread.start()
    return thread


# -- the estimator: the offline kernel, in pieces ------------------------------------------------------------------


def test_online_observer_is_the_offline_replay_in_pieces(log):
    """Fed in random pieces, the online observer holds the offline replay's theta and Gamma bit for bit, and its block
    sums add up to the replay's."""
    from wmrid.estimators.observer.online import OnlineObserver, online_estimate
    from wmrid.estimators.observer.replay import replay
    from wmrid.estimators.observer.settings import ObserverSettings
    from wmrid.model import dynamics as model
    from wmrid.model.dynamics import RegressorForm

    t, eta, tau = log
    form = RegressorForm("general")
    robot = wmrid.load_robot("paper")
    theta0 = model.intermediate_parameters(model.base_parameters(robot.nominal), form)
    settings = ObserverSettings(form, theta0, np.full_like(theta0, -np.inf), np.full_like(theta0, np.inf), k=10.0)
    offline = replay(t, eta, tau, settings)
    obs = OnlineObserver(settings)
    rng = np.random.default_rng(3)
    cuts = np.sort(rng.choice(np.arange(1, N), size=60, replace=False))
    for a, b in itertools.pairwise([0, *cuts, N]):
        obs.feed(t[a:b], eta[a:b], tau[a:b])
    assert np.array_equal(obs.theta, offline.theta)
    assert np.array_equal(obs.gamma, offline.gamma)
    blk_a, blk_c, _, _, ends = obs.blocks()
    np.testing.assert_allclose(blk_a.sum(axis=0), offline.blk_a.sum(axis=0), rtol=1e-10)
    np.testing.assert_allclose(blk_c.sum(axis=0), offline.blk_c.sum(axis=0), rtol=1e-10)
    assert len(ends) == pytest.approx(N // 10, abs=2)  # blocks of min(0.1, 0.1/k) = 0.01 s, as offline
    assert np.all(np.diff(ends) > 0)
    assert ends[-1] == t[-1]
    fine = OnlineObserver(settings, block_seconds=0.001)  # 5000 blocks: neighbours merged to stay within MAX_BLOCKS
    for a, b in itertools.pairwise([0, *cuts, N]):
        fine.feed(t[a:b], eta[a:b], tau[a:b])
    fine_a, _, _, _, fine_ends = fine.blocks()
    assert len(fine_ends) <= 4096
    assert fine.block_seconds == 0.002
    np.testing.assert_allclose(fine_a.sum(axis=0), offline.blk_a.sum(axis=0), rtol=1e-10)
    est = online_estimate(obs)
    assert est is not None
    assert est.segments >= 10
    assert est.parameters["m11"][0] == pytest.approx(0.7872544, rel=1e-3)  # the general form on a one-sign log


# -- framing: a torn last unit waits for its remainder -----------------------------------------------------------


def test_torn_mcap_record_waits_for_its_remainder(tmp_path, log):
    """An MCAP cut anywhere (in a record's header, inside a chunk) gives the same messages once the rest arrives, and
    the bytes it counts as read end on a record boundary."""
    from wmrid.io.live.framing import McapFramer

    path = tmp_path / "run.mcap"
    write_mcap(path, *log, chunked=True)
    data = path.read_bytes()
    whole = McapFramer("x", lambda topic, schema: True, 1 << 30)
    whole.push(data)
    assert whole.finished
    torn = McapFramer("x", lambda topic, schema: True, 1 << 30)
    for cut in (5, 9, 20, len(data) // 3, len(data) // 3 + 1, len(data) - 30):
        torn.push(data[torn.consumed + torn.held : cut])
        assert not torn.finished
        assert torn.consumed + torn.held == cut
        assert torn.consumed <= cut
    torn.push(data[torn.consumed + torn.held :])
    assert torn.finished
    assert torn.message_count == whole.message_count == N


# -- followed while written ---------------------------------------------------------------------------------------


def test_csv_being_appended_to(tmp_path, log):
    """A CSV grown in pieces (lines torn anywhere): the run ends after --idle; the final result is identify's on the
    finished file, read by name."""
    path = tmp_path / "run.csv"
    path.write_bytes(b"")
    writer = grow(path, csv_bytes(*log))
    updates, final = follow(path, idle=0.6)
    writer.join()
    assert final.samples == N
    assert "no data for 0.6 s" in final.reason
    assert final.read_from.endswith("itself")
    assert updates[-1].parameters
    assert updates[-1].samples == N
    same(final.result, wmrid.identify(str(path), "paper"))


def write_mcap(path, t, eta, tau, chunked: bool, pause_every: int = 0, pause: float = 0.0) -> None:
    """JointState messages on /joint_states: mcap_ros2's writer (4 KiB zstd chunks), or mcap's writer unchunked with
    mcap_ros2's serialiser; the file flushed and ``pause`` s slept every ``pause_every`` messages."""
    from mcap_ros2._dynamic import serialize_dynamic

    from wmrid.io.mcap.writer import JOINT_STATE_MSGDEF

    names = ["right_wheel_joint", "left_wheel_joint"]
    with open(path, "wb") as fh:
        if chunked:
            from mcap_ros2.writer import Writer

            writer = Writer(fh, chunk_size=4096)
            schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
        else:
            from mcap.writer import Writer as McapWriter

            writer = McapWriter(fh, use_chunking=False)
            writer.start(profile="ros2", library="test")
            sid = writer.register_schema("sensor_msgs/msg/JointState", "ros2msg", JOINT_STATE_MSGDEF.encode())
            cid = writer.register_channel("/joint_states", "cdr", sid)
            encode = serialize_dynamic("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)["sensor_msgs/msg/JointState"]
        for i in range(len(t)):
            ns = round(float(t[i]) * 1e9) + 1_700_000_000 * 10**9
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": names, "position": [0.0, 0.0], "velocity": [float(eta[i, 0]), float(eta[i, 1])],
                "effort": [float(tau[i, 0]), float(tau[i, 1])],
            }  # fmt: skip
            if chunked:
                writer.write_message("/joint_states", schema, msg, log_time=ns, publish_time=ns)
            else:
                writer.add_message(cid, log_time=ns, data=encode(msg), publish_time=ns)
            if pause_every and i % pause_every == 0:
                fh.flush()
                time.sleep(pause)
        writer.finish()


@pytest.mark.parametrize("chunked", [True, False], ids=["chunked", "unchunked"])
def test_mcap_being_written(tmp_path, log, chunked):
    """An MCAP written by a thread while wmrid.live follows it: the run ends at the footer (no --idle), and the final
    result is identify's on the finished file."""
    path = tmp_path / "run.mcap"
    path.write_bytes(b"")
    writer = threading.Thread(target=write_mcap, args=(path, *log, chunked, 400, 0.02), daemon=True)
    writer.start()
    updates, final = follow(path, idle=10.0)
    writer.join()
    assert "footer" in final.reason
    assert final.samples == N
    assert len(updates) >= 2
    assert updates[-1].parameters
    same(final.result, wmrid.identify(str(path), "paper"))


def test_a_long_streams_final_identify_runs_lean(tmp_path, log, monkeypatch):
    """Past FINAL_CACHE_ROWS samples (cut here to 100) the final identify keeps no copy of the log between its passes,
    reads it in smaller pieces and runs its passes on one thread (memory that of a short stream's: an hour at 1 kHz
    peaked at 1,137 MB), with the same result; the process's threading is given back after."""
    import wmrid.api.identification
    import wmrid.api.live
    from wmrid.core import wheel_log
    from wmrid.core.wheel_log import cache_rows, piece_rows
    from wmrid.estimators.observer.replay import second_thread
    from wmrid.runtime.limits import lean_malloc

    path = tmp_path / "run.mcap"
    write_mcap(path, *log, True, 0, 0.0)
    seen = []
    original = wmrid.api.identification.identify

    def spy(*args, **kwargs):
        seen.append((cache_rows(), piece_rows(), second_thread()))
        return original(*args, **kwargs)

    monkeypatch.setattr(wmrid.api.live, "FINAL_CACHE_ROWS", 100)
    monkeypatch.setattr(wmrid.api.identification, "identify", spy)
    _, final = follow(path, idle=10.0)
    assert seen == [(0, wmrid.api.live.FINAL_PIECE_ROWS, False)]
    assert second_thread()
    assert (cache_rows(), piece_rows()) == (wheel_log.CACHE_ROWS, wheel_log.CHUNK_ROWS)
    assert not lean_malloc()  # a library caller's malloc (not tuned by the command line) is left as it is
    monkeypatch.undo()
    same(final.result, wmrid.identify(str(path), "paper"))


def test_rosbag2_folder_split_in_two(tmp_path, log):
    """A rosbag2 folder (MCAP storage) recorded in two files: the second file is picked up once the first has its
    footer, the run ends when metadata.yaml appears, and the final result is identify's on the folder."""
    from tests.bagutil import recording, write_split_rosbag2

    one = tmp_path / "one.mcap"
    write_mcap(one, *log, chunked=True)
    staged = write_split_rosbag2(tmp_path / "staged", recording(one), storage="mcap", parts=2)
    folder = tmp_path / "run"
    folder.mkdir()

    def record() -> None:
        for name in sorted(p.name for p in staged.glob("*.mcap")):
            grow(folder / name, (staged / name).read_bytes(), pieces=10, pause=0.02).join()
        shutil.copyfile(staged / "metadata.yaml", folder / "metadata.yaml")

    writer = threading.Thread(target=record, daemon=True)
    writer.start()
    _, final = follow(folder, idle=10.0)
    writer.join()
    assert "metadata.yaml" in final.reason
    assert final.samples == N
    same(final.result, wmrid.identify(str(folder), "paper"))


def test_until_stops_and_identifies_what_was_read(tmp_path, log):
    """--until: the run stops after that much log time; the final result is identify's on a copy of the lines read."""
    path = tmp_path / "run.csv"
    path.write_bytes(csv_bytes(*log))
    _, final = follow(path, until=3.0)
    assert 3.0 <= final.log_time_s < 5.0
    assert "until" in final.reason
    assert final.result.log_info.samples == final.samples
    assert final.result.source == str(path)
    prefix = tmp_path / "prefix.csv"
    prefix.write_bytes(csv_bytes(*(a[: final.samples] for a in log)))
    same(final.result, wmrid.identify(str(prefix), "paper"))


# -- real processes: a pipe, and a stop ---------------------------------------------------------------------------


def start(*args: str, stdin=None) -> subprocess.Popen:
    env = dict(os.environ, COLUMNS=COLUMNS, PYTHONPATH=str(ROOT_DIR))
    return subprocess.Popen(
        [sys.executable, "-m", "wmrid", "live", *args], stdin=stdin, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, env=env,
    )  # fmt: skip


def test_stdin_pipe_json_lines_out(tmp_path, log):
    """`some_logger | wmrid live - --format json`: CSV rows written into the pipe in pieces; one JSON line per refresh,
    then the result line, whose parameters are identify's on the same rows."""
    data = csv_bytes(*log)
    proc = start("-", "--robot", "paper", "--every", "0.3", "-o", str(tmp_path / "r.json"), stdin=subprocess.PIPE)
    for i in range(0, len(data), 40_000):
        proc.stdin.write(data[i : i + 40_000])
        proc.stdin.flush()
        time.sleep(0.05)
    proc.stdin.close()
    proc.stdin = None  # closed: communicate only reads
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err.decode()
    lines = [json.loads(line) for line in out.decode().splitlines()]
    assert lines[-1]["event"] == "result"
    assert "end of standard input" in lines[-1]["reason"]
    assert {line["event"] for line in lines[:-1]} == {"update"}
    path = tmp_path / "run.csv"
    path.write_bytes(data)
    offline = wmrid.identify(str(path), "paper")
    saved = wmrid.IdentificationResult.from_dict(json.loads((tmp_path / "r.json").read_text()))
    same(saved, offline)
    assert lines[-1]["result"]["parameters"]["m11"]["value"] == pytest.approx(offline.parameters["m11"][0], rel=1e-12)


def test_json_lines_on_stdin():
    """JSON lines on standard input (in process): read as the CSV they turn into; the result is identify's on it."""
    from tests.cliutil import wmrid as run

    data = SAMPLE.read_bytes().splitlines()[:3001]
    keys = data[0].decode().split(",")
    lines = [json.dumps(dict(zip(keys, map(float, row.decode().split(",")), strict=True))) for row in data[1:]]
    proc = run("live", "-", "--robot", "paper", "--format", "json", stdin=("\n".join(lines) + "\n").encode())
    assert proc.returncode == 0, proc.stderr.decode()
    last = json.loads(proc.stdout.decode().splitlines()[-1])
    offline = run("identify", "-", "--robot", "paper", "--format", "json", stdin=b"\n".join(data) + b"\n")
    assert last["result"]["parameters"] == json.loads(offline.stdout)["parameters"]


def test_a_stream_with_a_gap_keeps_what_was_received(tmp_path, log):
    """Rows lost on the way (the stream's time jumps by 100 s, as when a bridge drops messages): the final identify
    refuses the hole as identify does, in one line that also says where the rows received are kept; that copy holds
    every row, and identify on it refuses the same way.  (It had been removed with the run's temporary folder.)"""
    import glob
    import tempfile

    from tests.cliutil import wmrid as run

    t, eta, tau = log
    t = t.copy()
    t[3000:] += 100.0
    before = set(glob.glob(os.path.join(tempfile.gettempdir(), "wmrid-live-received-*")))
    proc = run("live", "-", "--robot", "paper", "--format", "json", "-o", str(tmp_path / "r.json"),
               stdin=csv_bytes(t, eta, tau))  # fmt: skip
    err = proc.stderr.decode().strip().splitlines()
    (kept,) = set(glob.glob(os.path.join(tempfile.gettempdir(), "wmrid-live-received-*"))) - before
    try:
        assert proc.returncode == 1, err  # the log supports no result, as identify says
        assert len(err) == 1, err
        assert err[0].startswith(f"wmrid: error: {kept}: the log has a hole: time jumps by 100"), err[0]
        assert err[0].endswith(f"; {kept} keeps the {N:,} samples received"), err[0]
        assert Path(kept).read_bytes() == csv_bytes(t, eta, tau)
        assert not (tmp_path / "r.json").exists()
        again = run("identify", kept, "--robot", "paper")
        assert again.returncode == 1
        assert f"{kept}: the log has a hole" in again.stderr.decode()
    finally:
        os.remove(kept)


def test_each_update_line_reads_back_typed_and_writes_the_same_line():
    """The JSON lines `wmrid live` prints (in process, CSV rows on standard input): each update line read as a
    :class:`wmrid.LiveUpdate` writes back exactly the line it was read from (same keys, same order, same values), and
    the terminal's table is made from the typed update."""
    from tests.cliutil import wmrid as run
    from wmrid.reporting.live_view import json_line, live_table

    data = b"\n".join(SAMPLE.read_bytes().splitlines()[:3001]) + b"\n"
    proc = run("live", "-", "--robot", "paper", "--every", "0.01", "--format", "json", stdin=data)
    assert proc.returncode == 0, proc.stderr.decode()
    lines = [line for line in proc.stdout.decode().splitlines() if json.loads(line)["event"] == "update"]
    assert lines
    previous = None
    for line in lines:
        update = wmrid.LiveUpdate.from_dict(json.loads(line))
        assert json_line(update.to_dict()) == line
        assert wmrid.LiveUpdate.from_dict(update.to_dict()) == update
        live_table(update, previous)
        previous = update
    assert previous is not None
    assert previous.parameters  # the last update has an estimate
    assert previous.parameters["m11"][0] == json.loads(lines[-1])["parameters"]["m11"]["value"]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_stop_writes_the_result_so_far(tmp_path, log, signum):
    """Ctrl-C or SIGTERM while a CSV is still being written: -o holds identify's result on the lines read, exit
    128 + the signal, one line saying so."""
    path = tmp_path / "run.csv"
    data = csv_bytes(*log)
    path.write_bytes(data[: len(data) // 2])
    out = tmp_path / "r.json"
    proc = start(str(path), "--robot", "paper", "--every", "0.2", "-o", str(out))
    first = proc.stdout.readline()  # the first update: the run is following
    assert json.loads(first)["event"] == "update"
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signum, err.decode()
    assert "Traceback" not in err.decode()
    saved = json.loads(out.read_text())
    assert 1000 < saved["log"]["samples"] <= data[: len(data) // 2].count(b"\n") - 1  # whole rows written
    assert saved["parameters"]["m11"]["value"] == pytest.approx(0.787, rel=0.01)


def test_bad_input_is_one_line(tmp_path):
    """A source that cannot be followed: one `wmrid:` line, exit 2, no traceback."""
    from tests.cliutil import wmrid as run

    gz = tmp_path / "run.csv.gz"
    gz.write_bytes(b"\x1f\x8b\x08\x00" + bytes(20))
    for args, needle in (
        ([str(tmp_path / "missing.csv")], "no such file"),
        ([str(gz)], "compressed"),
        (["ws://:8765"], "not a WebSocket address"),
        ([str(SAMPLE), "--reconnect"], "--reconnect is for a WebSocket source"),
        ([str(SAMPLE), "--every", "0"], "--every"),
    ):
        proc = run("live", *args)
        err = proc.stderr.decode()
        assert proc.returncode == 2, err
        assert "Traceback" not in err
        assert len(err.strip().splitlines()) == 1, err
        assert needle in err, err


def test_live_drops_the_paper_form_when_the_sign_columns_speed_reverses_not_the_measured_one():
    """Live keeps a paper-form observer beside the general one until a wheel stops or reverses; it judged that by the
    measured speed, so a coarse encoder's derived speed dipping across zero for a sample dropped the paper form that
    the final identify (whose survey follows the sign columns' 20 ms mean) reports.  Now by the mean, as the final."""
    import numpy as np

    from wmrid.api.live_observers import _observer, fed
    from wmrid.estimators.observer.survey import survey
    from wmrid.estimators.options import ObserverOptions
    from wmrid.model.dynamics import RegressorForm
    from wmrid.model.robot import BUILTIN_ROBOTS

    rng = np.random.default_rng(3)
    t = np.arange(3000) * 1e-3
    eta = 5.0 + np.sin(t)[:, None] + rng.normal(0.0, 0.01, (3000, 2))
    tau = rng.normal(0.0, 1.0, (3000, 2))
    sv = survey([wmrid.WheelLog(t=t, eta=eta, tau=tau, source="x")], "x")
    robot = BUILTIN_ROBOTS["paper"]
    forms = (RegressorForm("paper", (1, 1)), RegressorForm("general"))
    observers = [(f, _observer(f, sv, robot, ObserverOptions())) for f in forms]
    dip = eta.copy()
    dip[1500, 0] = -0.5  # one sample the other way: the 21-sample mean stays > 0
    observers = fed(observers, t[:2000], dip[:2000], tau[:2000])
    assert [f.kind for f, _ in observers] == ["paper", "general"]
    back = eta[2000:].copy()
    back[200:400, 1] *= -1  # 0.2 s the other way: the mean follows
    observers = fed(observers, t[2000:], back, tau[2000:])
    assert [f.kind for f, _ in observers] == ["general"]
