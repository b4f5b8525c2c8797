"""``wmrid fleet`` on a real ``distributed.LocalCluster`` and on a scheduler and worker started as separate processes
(issue 17): a manifest run with per-log options, a bad log as an error row, a worker killed mid-run, ``--resume``
doing no work twice, the same command against both schedulers.  No mocks: real worker processes, real Parquet."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from locations import ROOT_DIR

from tests.cliutil import assert_clean_error, wmrid
from tests.fleetutil import write_fleet
from wmrid.fleets.run import fleet
from wmrid.fleets.table import read_table

ROOT = ROOT_DIR


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    """2 robots x 3 days of 6 s logs at 1 kHz, and one log that is not a log."""
    folder = tmp_path_factory.mktemp("fleet")
    write_fleet(folder, robots=2, days=3, duration=6.0)
    (folder / "R02" / "2026-01-09.csv").write_text("t,a\n0,1\n1,2\n")
    return folder


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 single-threaded worker processes (with nannies, which restart a killed worker)."""
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0",
                      silence_logs=logging.CRITICAL) as lc:  # fmt: skip
        yield lc.scheduler_address


def _params(row):
    return np.array([row[n] for n in ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")])


def test_a_run_gives_a_row_per_log_and_an_error_row(logs, cluster, tmp_path):
    out = tmp_path / "t.parquet"
    run = fleet([str(logs)], out, robot="paper", scheduler=cluster)
    assert run.identified == 7
    assert run.failed == 1
    assert run.workers == 2
    rows = read_table(out)
    assert rows == run.rows
    bad = [r for r in rows if r["error"] is not None]
    assert len(bad) == 1
    assert bad[0]["log"].endswith("2026-01-09.csv")
    assert "no columns 'eta_r'" in bad[0]["error"]
    good = [r for r in rows if r["error"] is None]
    assert [r["robot_id"] for r in good] == ["R01"] * 3 + ["R02"] * 3
    for r in good:
        assert r["samples"] == 6001
        assert r["duration_s"] == pytest.approx(6.0)
        assert r["start_time"].day in (1, 2, 3)
        assert r["time_source"] == "path"
        assert len(r["sha256"]) == 64
        assert r["method"] == "observer"
        assert r["fit_r"] > 95  # the model's simulated speeds on its own log
        assert r["run_time_s"] > 0
        assert r["M11"] == pytest.approx(1.41, rel=0.05)  # the paper robot, units spread by a few %
    # each row equals a bare identify of its log
    import wmrid

    first = good[0]
    bare = wmrid.identify(first["log"], "paper")
    np.testing.assert_array_equal(_params(first), bare.estimate.theta0)


def test_a_manifest_with_per_log_options(logs, cluster, tmp_path):
    # one log written again with its speeds in rpm and other column names: the manifest says so on its row
    src = logs / "R01" / "2026-01-01.parquet"
    frame = pd.read_parquet(src)
    frame = frame.assign(eta_r=frame.eta_r * 60 / (2 * np.pi), eta_l=frame.eta_l * 60 / (2 * np.pi))
    frame = frame.rename(columns={"eta_r": "vr", "eta_l": "vl"})
    frame.to_csv(tmp_path / "rpm.csv", index=False, float_format="%.17g")
    (tmp_path / "m.csv").write_text(
        "log,robot_id,time,speed_unit,columns\n"
        f"{src},R01,2026-02-01T10:00:00Z,,\n"
        'rpm.csv,R01-copy,2026-02-01T11:00:00Z,rpm,"t=t,eta_r=vr,eta_l=vl,tau_r=tau_r,tau_l=tau_l"\n'
    )
    root = os.path.commonpath([logs, tmp_path])  # the first log lies outside the manifest's folder
    run = fleet(manifest=tmp_path / "m.csv", manifest_root=root, output=tmp_path / "t.parquet", robot="paper",
                scheduler=cluster)  # fmt: skip
    a, b = run.rows
    assert (a["error"], b["error"]) == (None, None)
    assert b["time_source"] == "manifest"
    assert b["start_time"].hour == 11
    assert json.loads(b["options"]) == {"speed_unit": "rpm", "columns": "t=t,eta_r=vr,eta_l=vl,tau_r=tau_r,tau_l=tau_l"}
    # rpm -> rad/s and back rounds each speed by ~1e-16 relative; the estimator's weakly excited directions (the
    # friction) amplify that to ~1e-7 relative, still 1e-4 of a standard error: the same identification
    stds = np.array([a[f"{n}_std"] for n in ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")])
    assert np.all(np.abs(_params(b) - _params(a)) <= 1e-4 * stds)


def test_resume_does_no_work_twice(logs, cluster, tmp_path):
    out = tmp_path / "t.parquet"
    first = fleet([str(logs)], out, robot="paper", scheduler=cluster)
    with pytest.raises(Exception, match="--resume"):
        fleet([str(logs)], out, robot="paper", scheduler=cluster)  # an existing table: resume or force
    again = fleet([str(logs)], out, robot="paper", scheduler=cluster, resume=True)
    assert again.identified == 0
    assert again.skipped == 7  # the error row too: the same bytes fail the same way (retry_failed re-runs it)
    assert read_table(out) == first.rows  # not one cell changed: run times and workers are the first run's
    # one log's bytes change: that log only is identified again
    changed = logs / "R02" / "2026-01-03.parquet"
    saved = changed.read_bytes()
    try:
        frame = pd.read_parquet(changed)
        frame.iloc[::2].to_parquet(changed, index=False)
        third = fleet([str(logs)], out, robot="paper", scheduler=cluster, resume=True)
    finally:
        changed.write_bytes(saved)
    assert third.identified == 1
    assert third.skipped == 6
    row = next(r for r in third.rows if r["log"] == str(changed))
    assert row["samples"] == 3001
    # other options: a new run of every log, kept beside the old rows (both are in the table)
    fourth = fleet([str(logs)], out, robot="paper", scheduler=cluster, resume=True, retry_failed=True, k=20.0)
    assert fourth.identified == 7
    assert len(read_table(out)) == 14


def test_a_worker_killed_mid_run_still_gives_a_complete_table(logs, cluster, tmp_path):
    from distributed import Client

    with Client(cluster) as client:
        pids = client.run(os.getpid)
    killed: list[int] = []
    lock = threading.Lock()

    def progress(done, total, failed):
        with lock:
            if done == 1 and not killed:  # the first result is in: the other logs are queued or running
                pid = next(iter(pids.values()))
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)

    logs12 = [str(p) for p in sorted(logs.glob("*/*.parquet"))] * 1
    out = tmp_path / "t.parquet"
    run = fleet(logs12, out, robot="paper", scheduler=cluster, progress=progress, window=2, fit=False)
    assert killed
    assert run.identified == 6
    assert [r["error"] for r in run.rows] == [None] * 6
    assert len({r["log"] for r in read_table(out)}) == 6
    with Client(cluster) as client:  # the nanny started a new worker in place of the killed one
        client.wait_for_workers(2, timeout=60)
        assert killed[0] not in client.run(os.getpid).values()


def test_the_command_line_on_the_cluster(logs, cluster, tmp_path):
    proc = wmrid("fleet", str(logs / "R01"), "--robot", "paper", "--scheduler", cluster, "-o",
                 str(tmp_path / "t.parquet"), "--format", "json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["logs"] == 3
    assert summary["identified"] == 3
    assert summary["failed"] == 0
    assert summary["robots"] == 1
    assert summary["scheduler"] == cluster
    proc = wmrid("fleet", str(logs / "R01"), "--scheduler", cluster, "-o", str(tmp_path / "t.parquet"))
    assert_clean_error(proc, 2, "exists", "--resume", "--force")
    # --resume on the command line reads the table it then rewrites (it was refused as "the input")
    proc = wmrid("fleet", str(logs / "R01"), "--robot", "paper", "--scheduler", cluster, "-o",
                 str(tmp_path / "t.parquet"), "--resume", "--format", "json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    again = json.loads(proc.stdout)
    assert (again["identified"], again["resumed"], again["logs"]) == (0, 3, 3)


def _start(args: list[str], log: Path) -> subprocess.Popen:
    with log.open("wb") as out:  # the child has its own descriptor
        return subprocess.Popen([sys.executable, "-m", "dask", *args], cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)  # fmt: skip


def test_the_same_command_against_a_scheduler_started_separately(logs, cluster, tmp_path):
    # `dask scheduler` and `dask worker`, two processes of their own, as on a real cluster (the worker without a nanny
    # process: a nanny's restart of a killed worker is the LocalCluster test's); the command is the one run on the
    # LocalCluster, with only --scheduler changed, and it writes the same table (but for run times and workers)
    sched_file = tmp_path / "scheduler.json"
    scheduler = _start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--dashboard-address", "127.0.0.1:0",
                        "--scheduler-file", str(sched_file)], tmp_path / "scheduler.log")  # fmt: skip
    worker = None
    try:
        deadline = time.monotonic() + 60
        address = None
        while address is None and time.monotonic() < deadline:
            # the scheduler creates the file, then writes it: wait for a whole JSON document, not just the file
            try:
                address = json.loads(sched_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        assert address is not None, (tmp_path / "scheduler.log").read_text()
        worker = _start(["worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard", "--no-nanny"],
                        tmp_path / "worker.log")  # fmt: skip
        args = ["fleet", str(logs / "R02"), "--robot", "paper", "--no-fit", "--format", "json"]
        proc = wmrid(*args, "--scheduler", address, "-o", str(tmp_path / "remote.parquet"))
        assert proc.returncode == 0, proc.stderr.decode() + (tmp_path / "worker.log").read_text()
        assert json.loads(proc.stdout)["scheduler"] == address
        local = wmrid(*args, "--scheduler", cluster, "-o", str(tmp_path / "local.parquet"))  # the LocalCluster
        assert local.returncode == 0, local.stderr
    finally:
        for p in (worker, scheduler):
            if p is not None:
                os.killpg(p.pid, signal.SIGTERM)
                p.wait(timeout=30)
    remote_rows, local_rows = read_table(tmp_path / "remote.parquet"), read_table(tmp_path / "local.parquet")
    varying = {"run_time_s", "worker"}
    assert [{k: v for k, v in r.items() if k not in varying} for r in remote_rows] == [
        {k: v for k, v in r.items() if k not in varying} for r in local_rows
    ]
    assert len(remote_rows) == 4
    assert sum(r["error"] is not None for r in remote_rows) == 1


@pytest.mark.slow(reason="a real process with its own LocalCluster, stopped by Ctrl-C: about 15 s")
def test_ctrl_c_keeps_the_logs_done_and_resume_continues(tmp_path):
    """A fleet stopped by SIGINT: exit 130, the table holds the logs identified before the stop (written in the
    finally), the messages say so, no worker process is left; --resume then identifies only the rest."""
    import psutil

    write_fleet(tmp_path / "logs", robots=4, days=10, duration=20.0)  # 40 logs, about 2 s on 2 workers
    out = tmp_path / "t.parquet"
    args = [sys.executable, "-m", "wmrid", "fleet", str(tmp_path / "logs"), "--robot", "paper", "--workers", "2",
            "--batch", "1", "--checkpoint", "0.5", "-o", str(out)]  # fmt: skip
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and not out.exists():  # the first checkpoint: logs are being identified
        time.sleep(0.05)
    children = psutil.Process(proc.pid).children(recursive=True)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert f"wrote {out} before the stop" in err.decode()
    assert "--resume" in err.decode()
    done = read_table(out)
    assert 0 < len(done) < 40
    psutil.wait_procs(children, timeout=30)
    assert not [c for c in children if c.is_running() and c.status() != psutil.STATUS_ZOMBIE]
    again = fleet([str(tmp_path / "logs")], out, robot="paper", workers=2, resume=True)
    assert again.skipped == len(done)
    assert again.identified == 40 - len(done)
