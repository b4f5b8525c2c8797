"""Shared fixtures: small logs with a known truth, made here (no files needed)."""

from __future__ import annotations

import contextlib
import fcntl
import os
import pickle
import signal

import pytest

if "PYTEST_XDIST_WORKER" in os.environ and not {"OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"} & set(os.environ):
    # The workers use every core already (-n auto): OpenBLAS's own threads (one per core, in numpy's copy and in
    # scipy's) only compete with the other workers and spin while they wait, about 15 % of the run's CPU time.  Each
    # copy reads the count when it loads, here; the commands the tests start keep their default (a count the user set
    # is left alone).
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    try:
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401
    finally:
        del os.environ["OPENBLAS_NUM_THREADS"]

from tests.open_loop import open_loop_log


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: one worker more than the cores (3 on the 2-core CI machine).  Part of the suite waits rather than
    computes (real-time streams, the processes and servers it starts, signals it waits for), and a worker that waits
    leaves its core idle: the extra worker fills it (the default run 162 -> 150 s here, 2,393 tests)."""
    return (os.cpu_count() or 1) + 1


def _ignored(signum: int, frame: object) -> None:
    """A signal this test process was started ignoring: still ignored here (see below)."""


# The tests send SIGINT, SIGTERM and SIGHUP to the wmrid processes they start and check what a user at a terminal
# sees.  A run started with those signals ignored (under nohup, as a background job of a script) would hand the
# ignoring on to every child, and wmrid rightly keeps an ignored signal ignored: the tests would fail for the way
# the suite was launched.  An ignored signal is ignored here by a handler instead, which a child's exec resets to the
# default, as at a terminal; this process itself still ignores it.
for _sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT):
    if signal.getsignal(_sig) == signal.SIG_IGN:
        signal.signal(_sig, _ignored)


def made_once_per_run(tmp_path_factory, name: str, make):
    """``make()``, computed by one pytest-xdist worker of this run and read by the others from the run's shared
    temporary folder (under a lock: a worker that asks while another computes waits for it).  Outside xdist,
    simply ``make()``: nothing outlives the run, so no result of older code is ever read."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return make()
    root = tmp_path_factory.getbasetemp().parent  # this run's folder, shared by its workers
    path = root / f"{name}.pickle"
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if path.exists():
                return pickle.loads(path.read_bytes())
            value = make()
            tmp = path.with_suffix(".tmp")
            tmp.write_bytes(pickle.dumps(value))
            tmp.rename(path)
            return value
        finally:
            with contextlib.suppress(OSError):
                fcntl.flock(lock, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def smooth_log():
    return open_loop_log()


@pytest.fixture(scope="session")
def long_smooth_log():
    return open_loop_log(duration=40.0)


@pytest.fixture(scope="session")
def amr_caster_log(tmp_path_factory):
    """The light AMR on the MuJoCo multibody prototype: ball casters of rolling resistance 0.015, reversing at
    200 Hz, sensor noise 0.02 rad/s and 0.002 N m, seed 0 (issue 11's AMR configuration; 3-11 s to simulate,
    so made once per run and shared by every test that needs it)."""
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.multibody import simulate_multibody
    from wmrid.sim.multibody_model import MultibodySettings
    from wmrid.sim.scenario import NoiseSettings

    amr = BUILTIN_ROBOTS["amr"]
    return made_once_per_run(tmp_path_factory, "amr_caster_log", lambda: simulate_multibody(
        amr.cad, amr.nominal, casters=amr.casters, settings=MultibodySettings(caster_resistance=0.015),
        trajectory="reversing", rate=200, noise=NoiseSettings(eta_std=0.02, tau_std=0.002), seed=0,
    ))  # fmt: skip
