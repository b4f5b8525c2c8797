"""Golden identify results: the JSON ``wmrid identify`` writes for a set of logs that take every route through the
identification (each method; friction auto choosing the wheel, caster and load models; the timing check; split
topics; an applied delay and its timing term; the hold term of a slow log; the closed-loop check), kept in
``tests/data/golden/`` so that a change meant to move code, not numbers, can show it moved none.

Each golden file holds the SHA-256 of the whole JSON (wall-clock fields removed) and the JSON itself without its
history arrays (which the hash covers), so that a failure shows which field moved.  Written by
``python -m tests.golden --write [NAME ...]`` (from the checkout; it needs ``../shared/real_logs`` for the real logs).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

if __name__ == "__main__":
    # One OpenBLAS thread, as in the test run's workers (tests/conftest.py): with more, some results differ in their
    # last bits (the friction test's statistic on the MuJoCo log by 3e-11 relative), and the files would not match.
    os.environ["OPENBLAS_NUM_THREADS"] = "1"

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_logs"
REAL = ROOT.parent / "shared" / "real_logs"
GOLDEN = Path(__file__).resolve().parent / "data" / "golden"
#: Keys whose values are wall-clock times, not results: removed before comparing.
CLOCK_KEYS = frozenset({"seconds", "kernel_seconds"})


@dataclass(frozen=True)
class Case:
    """One golden result: ``identify LOG ARGS --format json``, the log made by ``log(folder)`` (a path)."""

    name: str
    log: Callable[[Path], Path]
    args: tuple[str, ...] = ()
    needs_real: bool = False
    slow: bool = True


def _sample(suffix: str) -> Callable[[Path], Path]:
    return lambda _folder: SAMPLES / f"paper_sinusoid.{suffix}"


def _real(*parts: str) -> Callable[[Path], Path]:
    return lambda _folder: REAL.joinpath(*parts)


def _simulated(name: str, *args: str, shift_s: float = 0.0) -> Callable[[Path], Path]:
    """A log ``wmrid simulate ARGS`` writes (CSV; ARGS as pairs of a flag's Python name and its value);
    ``shift_s``: its efforts then stamped that much late."""

    def make(folder: Path) -> Path:
        import pandas as pd

        from tests.cliutil import text, wmrid

        path = folder / f"{name}.csv"
        if path.exists():
            return path
        raw = folder / f"{name}.raw.csv" if shift_s else path
        flags = [f"--{args[i].replace('_', '-')}={args[i + 1]}" for i in range(0, len(args), 2)]
        proc = wmrid("simulate", "-o", str(raw), *flags)
        if proc.returncode != 0:
            raise AssertionError(f"{name}: simulate failed: {text(proc).stderr}")
        if not shift_s:
            return path
        frame = pd.read_csv(raw)
        t = frame["t"].to_numpy()
        late = {}
        for col in ("tau_r", "tau_l"):  # the effort at t is the one applied at t - shift_s
            late[col] = np.interp(t - shift_s, t, frame[col].to_numpy())
        keep = t >= t[0] + shift_s
        pd.DataFrame({**{c: frame[c].to_numpy() for c in frame.columns}, **late})[keep].to_csv(path, index=False)
        return path

    return make


ME169_A = _real("me169", "wheel_pwm_2022-04-13-14-27-37.mcap")
ME169_B = _real("me169", "wheel_pwm_2022-04-13-14-20-12.mcap")
ME169 = (
    "--velocity-topic", "/wheel_state", "--effort-topic", "/wheel_desired",
    "--right-joint", "rightwheel", "--left-joint", "leftwheel", "--effort", "pwm",
)  # fmt: skip
REGBOT = (
    "--columns", "t=1,eta_l=9,eta_r=10,tau_l=7,tau_r=8", "--speed-unit", "m/s", "--wheel-radius", "0.02975",
    "--effort", "current", "--torque-hold", "foh",
)  # fmt: skip
DRIVE = (
    "--columns",
    "t=ros_time,eta_l=meas_left_vel,eta_r=meas_right_vel,tau_l=left_wheel_current,tau_r=right_wheel_current",
    "--effort", "current",
)  # fmt: skip
CLOSED = ("trajectory", "reversing", "duration", "20", "eta_noise", "0.01", "tau_noise", "0.01", "caster", "0.02")
PAPER = ("--robot", "paper")
AMR = ("--robot", str(ROOT / "examples" / "small_amr.toml"))
MUJOCO = ("robot", AMR[1], "engine", "mujoco", "trajectory", "reversing", "duration", "20", "eta_noise", "0.01",
          "tau_noise", "0.01")  # fmt: skip

CASES = (
    Case("sample_csv_auto", _sample("csv"), PAPER, slow=False),
    *(Case(f"sample_csv_{m}", _sample("csv"), (*PAPER, "--method", m)) for m in ("observer", "idim", "rls", "oe")),
    Case("sample_parquet_auto", _sample("parquet"), PAPER),
    Case("sample_mcap_auto", _sample("mcap"), PAPER),
    Case("sample_csv_no_robot", _sample("csv")),
    Case("sample_csv_payload_validate", _sample("csv"),
         (*PAPER, "--payload", "--validate", str(SAMPLES / "paper_sinusoid.parquet"))),
    Case("closed_loop_auto", _simulated("closed", *CLOSED), PAPER),
    Case("closed_loop_caster", _simulated("closed", *CLOSED), (*PAPER, "--friction", "wheel+caster")),
    Case("closed_loop_idim", _simulated("closed", *CLOSED), (*PAPER, "--method", "idim")),
    Case("closed_loop_iv", _simulated("closed", *CLOSED), (*PAPER, "--method", "iv")),
    Case("closed_loop_late_efforts", _simulated("late", *CLOSED, shift_s=0.012), PAPER, slow=False),
    Case("closed_loop_delay_auto", _simulated("late", *CLOSED, shift_s=0.012), (*PAPER, "--delay", "auto")),
    Case("closed_loop_delay_given", _simulated("late", *CLOSED, shift_s=0.012), (*PAPER, "--delay", "0.012")),
    Case("slow_50hz", _simulated("slow", *CLOSED, "rate", "50"), PAPER),
    Case("slow_50hz_foh", _simulated("slow", *CLOSED, "rate", "50"), (*PAPER, "--torque-hold", "foh")),
    Case("slow_50hz_control_rate", _simulated("slow", *CLOSED, "rate", "50"), (*PAPER, "--control-rate", "1000")),
    Case("mujoco_amr_auto", _simulated("amr", *MUJOCO), AMR),
    Case("mujoco_amr_wheel_idim", _simulated("amr", *MUJOCO), (*AMR, "--friction", "wheel", "--method", "idim")),
    Case("mujoco_amr_late_idim", _simulated("amr_late", *MUJOCO, shift_s=0.012), (*AMR, "--method", "idim")),
    Case("mujoco_amr_late_auto", _simulated("amr_late", *MUJOCO, shift_s=0.012), AMR),
    Case("me169_auto", ME169_A, ME169, needs_real=True),
    Case("me169_idim", ME169_A, (*ME169, "--method", "idim"), needs_real=True),
    Case("me169_wheel", ME169_B, (*ME169, "--friction", "wheel"), needs_real=True),
    Case("regbot", _real("regbot", "square_1.txt"), REGBOT, needs_real=True),
    Case("drive_husky", _real("drive", "husky_avide_2024_11_3_15h4s4.parquet"), DRIVE, needs_real=True),
    Case("drive_warthog_rls", _real("drive", "warthog_test_close.parquet"), (*DRIVE, "--method", "rls"),
         needs_real=True),
)  # fmt: skip


def _without_clock(value: object) -> object:
    if isinstance(value, dict):
        return {k: _without_clock(v) for k, v in value.items() if k not in CLOCK_KEYS}
    if isinstance(value, list):
        return [_without_clock(v) for v in value]
    return value


def capture(case: Case, folder: Path) -> dict[str, object]:
    """The golden record of ``case``: {"args", "sha256", "result"} (result: the JSON without its history)."""
    from tests.cliutil import text, wmrid

    folder.mkdir(parents=True, exist_ok=True)
    log = case.log(folder)
    proc = wmrid("identify", str(log), *case.args, "--format", "json")
    if proc.returncode != 0:
        raise AssertionError(f"{case.name}: identify failed: {text(proc).stderr}")
    out = proc.stdout.decode()
    for path, mark in ((REAL, "<real_logs>"), (ROOT, "<checkout>"), (folder, "<folder>")):
        out = out.replace(str(path), mark)
    result = _without_clock(json.loads(out))
    whole = json.dumps(result, sort_keys=True, allow_nan=True)
    trimmed = {k: v for k, v in result.items() if k != "history"}
    args = [a.replace(str(ROOT), "<checkout>") for a in case.args]
    return {"args": args, "sha256": hashlib.sha256(whole.encode()).hexdigest(), "result": trimmed}


def one_blas_thread() -> bool:
    """Whether numpy's OpenBLAS in this process runs one thread, as the golden files were written with."""
    return os.environ.get("OPENBLAS_NUM_THREADS") == "1" or "PYTEST_XDIST_WORKER" in os.environ


def capture_in_process_of_one_thread(case: Case, folder: Path) -> dict[str, object]:
    """:func:`capture`, in this process when its OpenBLAS runs one thread, else in a child process that does."""
    if one_blas_thread():
        return capture(case, folder)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "tests.golden", "--print", case.name, str(folder)],
        cwd=ROOT, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    if proc.returncode != 0:
        raise AssertionError(f"{case.name}: {proc.stderr}")
    return json.loads(proc.stdout)


def path_of(case: Case) -> Path:
    return GOLDEN / f"{case.name}.json"


def main(argv: list[str]) -> int:
    import tempfile

    names = [a for a in argv if not a.startswith("--")]
    if argv[:1] == ["--print"]:
        (case,) = [c for c in CASES if c.name == names[0]]
        print(json.dumps(capture(case, Path(names[1])), allow_nan=True))
        return 0
    if "--write" not in argv:
        print("usage: python -m tests.golden --write [NAME ...]", file=sys.stderr)
        return 2
    GOLDEN.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            if names and case.name not in names:
                continue
            record = capture(case, Path(tmp))
            path_of(case).write_text(json.dumps(record, indent=1, sort_keys=True, allow_nan=True) + "\n")
            print(case.name, record["sha256"][:12])
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
