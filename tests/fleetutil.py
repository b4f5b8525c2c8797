"""Small simulated fleets for the fleet tests (a helper module, not a test module).

:func:`write_fleet` writes ``folder/R01/2026-01-01.parquet`` ... with wmrid's simulator (seeded); :func:`synthetic_rows`
makes table rows directly from chosen parameter series (no identification), for the review's tests.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import replace
from pathlib import Path

import numpy as np

START = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)


def write_fleet(
    folder: Path, robots: int = 2, days: int = 3, duration: float = 6.0, *, drift: dict | None = None,
    payload: dict | None = None, seed: int = 5,
) -> list[Path]:  # fmt: skip
    """Logs of ``robots`` robots x ``days`` days (t, eta_r, eta_l, tau_r, tau_l; 1 kHz, noise 0.01 rad/s and
    0.02 N m).  drift: {robot index: (wheel "right"/"left", relative rise per day, onset day)}; payload: {robot
    index: (kg, x, y, from day)}.  Units differ by 3 % in mass and 15 % in friction; days by 1 % in friction."""
    import wmrid
    from wmrid.io.logs import write_log
    from wmrid.model.robot import BUILTIN_ROBOTS

    paper = BUILTIN_ROBOTS["paper"]
    paths = []
    for u in range(robots):
        rng = np.random.Generator(np.random.PCG64([seed, u]))
        f = np.exp(0.15 * rng.standard_normal(4))
        cad = replace(paper.cad, m_p=paper.cad.m_p * (1 + 0.03 * rng.standard_normal()), F_v1=paper.cad.F_v1 * f[0],
                      F_v2=paper.cad.F_v2 * f[1], F_d1=paper.cad.F_d1 * f[2], F_d2=paper.cad.F_d2 * f[3])  # fmt: skip
        for day in range(days):
            day_rng = np.random.Generator(np.random.PCG64([seed, u, day]))
            k = 1 + 0.01 * day_rng.standard_normal(4)
            if drift and u in drift:
                wheel, rate, onset = drift[u]
                k[[0, 2] if wheel == "right" else [1, 3]] *= 1 + rate * max(0, day - onset)
            robot = replace(paper, cad=replace(cad, F_v1=cad.F_v1 * k[0], F_v2=cad.F_v2 * k[1], F_d1=cad.F_d1 * k[2],
                                               F_d2=cad.F_d2 * k[3]))  # fmt: skip
            load = None
            if payload and u in payload and day >= payload[u][3]:
                load = wmrid.Payload(payload[u][0], payload[u][1], payload[u][2])
            run = wmrid.simulate(
                robot,
                duration=duration,
                payload=load,
                noise=wmrid.NoiseSettings(seed=int(day_rng.integers(2**31)), eta_std=0.01, tau_std=0.02),
            )
            path = folder / f"R{u + 1:02d}" / f"{(START + dt.timedelta(days=day)).date()}.parquet"
            path.parent.mkdir(parents=True, exist_ok=True)
            write_log(run.to_frame()[["t", "eta_r", "eta_l", "tau_r", "tau_l"]], str(path))
            paths.append(path)
    return paths


#: Typical values and log-to-log scatter of the watched parameters (the paper robot, 60 s logs).
LEVEL = {"M11": 1.41, "M12": -0.455, "M22": 1.49, "Vc": 0.21, "Fv1": 0.010, "Fv2": 0.015, "Fd1": 0.045, "Fd2": 0.040}
SCATTER = {"M11": 3e-4, "M12": 3e-4, "M22": 3e-4, "Vc": 1e-4, "Fv1": 1.5e-4, "Fv2": 2e-4, "Fd1": 6e-4, "Fd2": 5e-4}


#: The multibody prototype's friction, as the fleet review sees it (docs/how-to/fleet-dask.md): each log trades Fv
#: against Fd (their estimates correlate at -0.95; 15 % of Fv log to log), their sum at the wheels' typical speed
#: (4 rad/s) scatters by 1 %, and the reported std holds a model error common to every log (3x Fv's value).
TRADE = {"speed": 4.0, "fv_scatter": 0.15, "fw_scatter": 0.01, "corr": -0.95, "fv_std": 3.0, "fd_std": 1.0}


def synthetic_rows(
    robots: int = 8, days: int = 40, *, changes: dict | None = None, seed: int = 3, robot: str = "paper",
    unit_spread: float = 0.03, trade: bool = False,
) -> list[dict]:  # fmt: skip
    """Fleet-table rows whose watched parameters are drawn directly: each unit's level (relative spread
    ``unit_spread``), Gaussian log-to-log scatter (:data:`SCATTER`), and ``changes`` {robot index: function(day,
    values dict) -> None that edits the values in place}.  Reported std: half the scatter.

    trade : friction as on the multibody prototype (:data:`TRADE`): per wheel, Fw = Fd + 4 Fv scatters by 1 % and Fv
    by 15 %, Fd taking up the difference; the rows carry the wheels' mean speeds and the Fv-Fd correlations (a
    change edits Fv and Fd, applied after the trade)."""
    from wmrid.fleets.table import empty_row

    rng = np.random.Generator(np.random.PCG64(seed))
    rows = []
    for u in range(robots):
        level = {n: v * (1 + unit_spread * rng.standard_normal()) for n, v in LEVEL.items()}
        for day in range(days):
            values = {n: level[n] + SCATTER[n] * rng.standard_normal() for n in LEVEL}
            stds = {f"{n}_std": SCATTER[n] / 2 for n in LEVEL}
            extra = {}
            if trade:
                w = TRADE["speed"]
                for v, d, speed, corr in (("Fv1", "Fd1", "speed_r", "Fv1_Fd1_corr"),
                                          ("Fv2", "Fd2", "speed_l", "Fv2_Fd2_corr")):  # fmt: skip
                    fw = (level[d] + w * level[v]) * (1 + TRADE["fw_scatter"] * rng.standard_normal())
                    values[v] = level[v] * (1 + TRADE["fv_scatter"] * rng.standard_normal())
                    values[d] = fw - w * values[v]
                    stds[f"{v}_std"], stds[f"{d}_std"] = TRADE["fv_std"] * level[v], TRADE["fd_std"] * level[d]
                    extra[speed] = w * (1 + 0.01 * rng.standard_normal())
                    extra[corr] = TRADE["corr"]
            if changes and u in changes:
                changes[u](day, values)
            rows.append(empty_row(
                robot_id=f"R{u + 1:02d}", log=f"R{u + 1:02d}/{day}.parquet", robot=robot,
                start_time=START + dt.timedelta(days=day), options="{}", options_key="k", sha256=f"{u}-{day}",
                **values, **stds, **extra,
            ))  # fmt: skip
    return rows
