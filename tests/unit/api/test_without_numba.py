"""The core install without numba (``pip install wmrid``; numba comes with the ``fast`` extra): every kernel runs as
the plain Python function it is written as (wmrid.core.jit), and gives what the compiled kernel gives.

A real interpreter in which numba cannot be imported (a ``sitecustomize`` on its path refuses numba and llvmlite, as
an environment without them would) reads a CSV log, a ROS 1 bag and a rosbag2 folder of MCAP storage (the binary
scanners), identifies the log, compares the methods on it (the observer, IDIM, IDIM-IV and RLS: their filters and
recursions), predicts its speeds from the estimate (output error's kernel; output error itself is scipy's least
squares around it), and simulates (the closed-loop simulator, and one that diverges); this process does the same
with numba.

Tolerance: decoded logs equal exactly (integer and bit operations); estimates and simulations to 1e-12 relative.  The
kernels are the same operations in the same order (numba compiles without fast-math, so LLVM neither reorders nor
contracts them); what may differ is the last bit of a libm function (exp, expm1) and what follows from it: measured
1e-15 relative on a 40 s simulation, identical estimates on the bundled sample.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tests.bagutil import recording, write_ros1, write_rosbag2
from tests.locations import ROOT_DIR as REPO

BLOCKER = '''
import sys


class _NoNumba:
    """numba and llvmlite cannot be imported here, as where they are not installed."""

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("numba", "llvmlite"):
            raise ImportError(f"No module named {name!r} (blocked: wmrid is tested without numba)")
        return None


sys.meta_path.insert(0, _NoNumba())
'''

#: What both interpreters run: ``results(csv, bag, folder)`` of a CSV log, a ROS 1 bag and a rosbag2 folder, as JSON.
BODY = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    import wmrid
    from wmrid.core import jit
    from wmrid.model.predict import simulate_speeds


    def results(csv, bag, folder):
        out = {"compiled": jit.COMPILED}
        for name, path in (("csv", csv), ("ros1", bag), ("rosbag2", folder)):
            log = wmrid.read_log(path)
            out[name] = [np.asarray(log.t).tolist(), np.asarray(log.eta).tolist(), np.asarray(log.tau).tolist()]
        out["identify"] = wmrid.identify(csv, "paper").to_dict(history=False)["parameters"]
        # output error's kernel is the predictor's (below): its 3 s of plain-Python least squares add nothing
        methods = wmrid.compare(csv, "paper", methods=["observer", "idim", "iv", "rls"]).to_dict()["methods"]
        out["compare"] = {m: r.get("parameters") for m, r in methods.items()}
        log = wmrid.read_log(csv)
        names = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
        theta0 = np.array([out["identify"][n]["value"] for n in names])
        out["predict"] = simulate_speeds(log.t, log.tau, theta0, log.eta[0]).tolist()
        run = wmrid.simulate(duration=0.5)
        out["simulate"] = [np.asarray(run.log.eta).tolist(), np.asarray(run.log.tau).tolist()]
        try:  # a closed loop that diverges: one clear error either way (not a log of NaNs, not a crash)
            wmrid.simulate(duration=0.3, noise=wmrid.NoiseSettings(caster_std=1e200))
            out["diverged"] = "no error"
        except wmrid.WmridError as err:
            out["diverged"] = str(err)
        out["numba_loaded"] = "numba" in sys.modules
        return json.loads(json.dumps(out))
    """
)


def _without_numba(blocker: Path, args: list[str], tmp_path: Path) -> dict:
    """:data:`BODY`'s results in a new interpreter where numba cannot be imported (``blocker`` holds the
    ``sitecustomize`` that refuses it)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(blocker), str(REPO), env.get("PYTHONPATH")) if p)
    code = f"{BODY}\nprint(json.dumps(results(*sys.argv[1:4])))"
    done = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def _close(a, b, where: str = "") -> None:
    """``a`` and ``b`` (nested JSON) equal, floats to 1e-12 relative (NaN equal to NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _close(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) or math.isnan(b):
            assert math.isnan(a), where
            assert math.isnan(b), where
        else:
            assert a == pytest.approx(b, rel=1e-12, abs=1e-300), where
    else:
        assert a == b, where


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """(without numba, with numba): :data:`BODY`'s results in a new interpreter and in this one, on the same files."""
    import wmrid

    tmp = tmp_path_factory.mktemp("no_numba")
    (tmp / "blocker").mkdir()
    (tmp / "blocker" / "sitecustomize.py").write_text(BLOCKER)
    # 1.5 s of a simulated drive with its set-points (IDIM-IV needs them), and 300 messages of the bundled MCAP
    simulated = tmp / "drive.csv"
    wmrid.write_simulation(wmrid.simulate(duration=1.5), simulated)
    messages = recording(REPO / "sample_logs" / "paper_sinusoid.mcap")[:300]
    bag = write_ros1(tmp / "drive.bag", messages)
    folder = write_rosbag2(tmp / "drive_mcap", messages, storage="mcap")
    args = [str(simulated), str(bag), str(folder)]
    namespace: dict = {}
    exec(BODY, namespace)  # the same code as the other interpreter runs
    return _without_numba(tmp / "blocker", args, tmp), namespace["results"](*args)


def test_the_core_runs_without_numba(both):
    plain, compiled = both
    assert plain["compiled"] is False
    assert plain["numba_loaded"] is False
    assert compiled["compiled"] is True
    assert compiled["numba_loaded"] is True


@pytest.mark.parametrize("fmt", ["csv", "ros1", "rosbag2"])
def test_logs_decode_the_same_without_numba(both, fmt):
    plain, compiled = both
    assert len(plain[fmt][0]) > 100
    assert plain[fmt] == compiled[fmt]  # exactly: the scanners do integer and bit operations


@pytest.mark.parametrize("what", ["identify", "compare", "predict", "simulate", "diverged"])
def test_estimates_and_simulations_are_the_same_without_numba(both, what):
    plain, compiled = both
    _close(plain[what], compiled[what], what)
    if what == "compare":
        assert set(plain[what]) == {"observer", "idim", "iv", "rls"}
        assert all(plain[what].values())
    if what == "simulate":
        assert np.isfinite(np.asarray(plain[what][0])).all()
    if what == "diverged":
        assert plain[what].startswith("the simulation diverged at t = ")


def test_a_long_log_without_numba_says_once_how_long_and_how_to_shorten_it(monkeypatch, tmp_path):
    """The note a user of a long log sees without numba: one line on stderr, before the work, with the estimated time
    and the extra's install command; nothing on stdout but the result.  (The threshold is lowered to the bundled
    sample's 40,001 samples, and numba counted as absent; the plain-Python run itself is tested above.)"""
    from tests.cliutil import wmrid as run
    from wmrid.core import jit

    monkeypatch.setattr(jit, "COMPILED", False)
    monkeypatch.setattr(jit, "SLOW_FROM_SAMPLES", 40_000)
    sample = REPO / "sample_logs" / "paper_sinusoid.csv"
    done = run("identify", sample, "--robot", "paper", "--format", "json", cwd=tmp_path)
    assert done.returncode == 0
    assert json.loads(done.stdout)["parameters"]
    assert done.stderr.decode() == (
        "wmrid: note: numba is not installed, so the estimator runs as plain Python: about 12 s for these 40,001 "
        "samples, seconds with it (pip install 'wmrid[fast]')\n"
    )
    monkeypatch.setattr(jit, "COMPILED", True)
    done = run("identify", sample, "--robot", "paper", "--format", "json", cwd=tmp_path)
    assert done.returncode == 0
    assert done.stderr == b""


def _note_runs(monkeypatch, tmp_path, *commands, broken=None):
    """stderr of each of ``commands`` (wmrid arguments), numba counted as absent (``broken``: installed but not
    importable, with that error) and the note's threshold lowered to 10,000 samples."""
    from tests.cliutil import wmrid as run
    from wmrid.core import jit

    monkeypatch.setattr(jit, "COMPILED", False)
    monkeypatch.setattr(jit, "BROKEN", broken)
    monkeypatch.setattr(jit, "SLOW_FROM_SAMPLES", 10_000)
    errs = []
    for argv in commands:
        done = run(*argv, cwd=tmp_path)
        assert done.returncode == 0, done.stderr.decode()
        errs.append(done.stderr.decode())
    return errs


def test_the_note_is_said_once_per_command_whatever_the_route(monkeypatch, tmp_path):
    """compare (five methods), an applied delay (identify's other route) and monitor (its windows each shorter than
    the threshold) each say the note once, with the whole log's samples."""
    sample = REPO / "sample_logs" / "paper_sinusoid.csv"
    model = tmp_path / "model.json"
    errs = _note_runs(
        monkeypatch, tmp_path,
        ["identify", sample, "--robot", "paper", "-o", model],
        ["compare", sample, "--robot", "paper", "--format", "json"],
        ["identify", sample, "--robot", "paper", "--delay", "0.001", "--format", "json"],
        ["monitor", sample, "--model", model, "--format", "json"],
    )  # fmt: skip
    for err in errs:
        notes = [line for line in err.splitlines() if line.startswith("wmrid: note: ")]
        assert len(notes) == 1, err
        assert "for these 40,001 samples" in notes[0]


def test_a_numba_that_cannot_be_imported_is_said_as_such(monkeypatch, tmp_path):
    """numba installed but not importable (e.g. a NumPy newer than it supports) is not "not installed": installing
    the extra again would change nothing."""
    sample = REPO / "sample_logs" / "paper_sinusoid.csv"
    (err,) = _note_runs(
        monkeypatch, tmp_path, ["identify", sample, "--robot", "paper", "--format", "json"],
        broken="Numba needs NumPy 2.2 or less. Got NumPy 2.4.",
    )  # fmt: skip
    assert err == (
        "wmrid: note: numba is installed but cannot be imported (Numba needs NumPy 2.2 or less. Got NumPy 2.4.), so "
        "the estimator runs as plain Python: about 12 s for these 40,001 samples, seconds once numba imports\n"
    )


def test_plain_kernels_do_numbas_arithmetic():
    """A kernel run as plain Python: a division by zero raises ZeroDivisionError, as compiled with numba's error
    model (numpy's scalars would give inf and a warning); an overflow gives inf silently, as compiled code does."""
    import warnings

    from wmrid.core.jit import _as_compiled

    def divide(a, b):
        return a[0] / b[0]

    def overflow(a):
        return a[0] * a[0]

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any RuntimeWarning fails the test
        with pytest.raises(ZeroDivisionError):
            _as_compiled(divide)(np.ones(1), np.zeros(1))
        assert _as_compiled(overflow)(np.array([1e200])) == np.inf
        assert _as_compiled(divide)(np.array([3.0]), np.array([2.0])) == 1.5
