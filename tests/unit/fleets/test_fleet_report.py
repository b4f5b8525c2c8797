"""``wmrid fleet-report`` (issue 17): on tables with known changes it flags exactly the robots that changed, dates the
changes, estimates a payload, finds the robot that stands out, ranks them; the page is self-contained; the command
line's outputs and errors."""

from __future__ import annotations

import base64
import datetime as dt
import json
import re

import numpy as np
import pytest
import svgutil

from tests.cliutil import assert_clean_error, wmrid
from tests.fleetutil import START, synthetic_rows, write_fleet
from wmrid.fleets.report import fleet_report, write_fleet_report
from wmrid.fleets.table import write_table
from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS, Payload

CAD = BUILTIN_ROBOTS["paper"].cad


def _payload_step(day0: int, load: Payload):
    """Adds the change of M and V_c that ``load`` makes on the paper robot, from day ``day0`` on."""
    m0, m1 = model.inertia_matrix(CAD), model.inertia_matrix(CAD.with_payload(load))
    dvc = model.coriolis_coefficient(CAD.with_payload(load)) - model.coriolis_coefficient(CAD)
    delta = {"M11": m1[0, 0] - m0[0, 0], "M12": m1[0, 1] - m0[0, 1], "M22": m1[1, 1] - m0[1, 1], "Vc": dvc}

    def change(day, values):
        if day >= day0:
            for k, v in delta.items():
                values[k] += v

    return change


def _wear(day0: int, rate: float, names=("Fv1", "Fd1")):
    def change(day, values):
        for n in names:
            values[n] *= 1 + rate * max(0, day - day0)

    return change


def _odd(values_day: int, name: str, factor: float):
    def change(day, values):
        if day == values_day:
            values[name] *= factor

    return change


@pytest.fixture(scope="module")
def rows():
    """10 robots x 40 days: R02 right-wheel wear (+3 %/day from day 15), R05 a 10 kg payload from day 25, R08 a
    left Coulomb friction 40 % above its siblings, R09 one odd log on day 20; the others nothing."""
    out = synthetic_rows(10, 40, changes={1: _wear(15, 0.03), 4: _payload_step(25, Payload(10.0, 0.05, -0.03)),
                                          8: _odd(20, "Fv2", 1.6)})  # fmt: skip
    for r in out:
        if r["robot_id"] == "R08":
            r["Fd2"] *= 1.4
    return out


@pytest.fixture(scope="module")
def report(rows):
    return fleet_report(rows, robot="paper")


def _by_id(rep):
    return {rv.robot_id: rv for rv in rep.review.robots}


def test_exactly_the_changed_robots_are_flagged(report):
    robots = _by_id(report)
    flagged = {rid for rid, rv in robots.items() if rv.flagged}
    assert flagged == {"R02", "R05", "R08"}
    assert robots["R02"].flags == ["wheel wear? (right)"]
    assert robots["R05"].flags == ["payload or configuration change"]
    assert robots["R08"].flags == ["stands out from the fleet"]
    assert [rv.robot_id for rv in report.review.robots[:3]] == sorted(
        flagged, key=lambda rid: -robots[rid].evidence
    )  # ranked by the evidence


def test_changes_are_dated(report):
    robots = _by_id(report)
    wear = robots["R02"].history.changes[0]
    assert wear.kind == "ramp"
    assert 15 <= wear.onset <= 17  # the first log that differs is day 16
    assert wear.alarm - 15 <= 5
    step = robots["R05"].history.changes[0]
    assert step.onset == step.alarm == 25
    assert step.kind == "step"
    assert "from 2026-01-26 (flagged 2026-01-26)" in robots["R05"].findings[0]


def test_the_payload_is_estimated_against_the_robots_own_logs(report):
    payload = _by_id(report)["R05"].payload
    mass, std = payload["mass"]
    assert abs(mass - 10.0) <= 3 * std  # a 3-std band around the truth; std from the logs' scatter
    assert std < 0.5
    x, sx = payload["x"]
    assert abs(x - 0.05) <= 3 * sx


def test_an_odd_log_is_listed_not_flagged(report):
    r09 = _by_id(report)["R09"]
    assert not r09.flagged
    assert r09.history.odd_logs == [20]
    assert any("odd log" in f and "2026-01-21" in f for f in r09.findings)


def test_a_robot_without_change_is_not_flagged_over_many_fleets():
    # 30 fleets of 10 unchanged robots (300 robot histories) at alpha = 0.001 per robot and 0.001 per model:
    # expected false flags 0.3 + 0.03; more than 3 would reject the stated rate (Poisson(0.33) > 3: p < 5e-4)
    flags = 0
    for seed in range(30):
        rep = fleet_report(synthetic_rows(10, 30, seed=100 + seed), figures=False)
        flags += sum(rv.flagged for rv in rep.review.robots)
    assert flags <= 3


def test_html_report_is_self_contained(rows, tmp_path):
    table = tmp_path / "t.parquet"
    write_table([r for r in rows if r["robot_id"] <= "R05"], table)  # the wear and the payload, 5 robots
    rep = fleet_report(table, robot="paper", command="wmrid fleet-report t.parquet")
    write_fleet_report(rep, tmp_path / "r.html")
    page = (tmp_path / "r.html").read_text()
    assert page.count("<svg") == 1 + 5  # the evidence and every robot
    assert "Robots ranked by the evidence against them" in page
    assert "wheel wear? (right)" in page
    assert "payload ≈ " in page
    assert "What a flag means" in page
    import hashlib

    assert hashlib.sha256(table.read_bytes()).hexdigest() in page
    assert not re.search(r"<script|<link|<iframe|<object|<embed|@import|(src|href)=['\"]?https?:", page)
    write_fleet_report(rep, tmp_path / "r.md")
    md = (tmp_path / "r.md").read_text()
    assert md.count("data:image/svg+xml;base64,") == 5
    first = re.search(r"data:image/svg\+xml;base64,([A-Za-z0-9+/=]+)\)", md).group(1)
    assert svgutil.panels(svgutil.parse(base64.b64decode(first)))  # an SVG figure, whole
    write_fleet_report(rep, tmp_path / "r.json")
    data = json.loads((tmp_path / "r.json").read_text())
    assert {r["robot_id"] for r in data["robots"] if r["flagged"]} == {"R02", "R05"}
    assert data["settings"] == {"baseline": 10, "window": 30, "alpha": 0.001, "outlier_alpha": 0.001}


def test_the_command_line(rows, tmp_path):
    table = tmp_path / "t.parquet"
    write_table(rows, table)
    proc = wmrid("fleet-report", str(table), "--format", "json")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert {r["robot_id"] for r in data["robots"] if r["flagged"]} == {"R02", "R05", "R08"}
    proc = wmrid("fleet-report", str(table), "--format", "table", columns="80")
    out = proc.stdout.decode()
    assert proc.returncode == 0
    assert "Robots ranked by the evidence against them" in out
    assert "R02: wheel wear? right wheel's friction rising from 2026-01-1" in " ".join(out.split())
    assert max(len(line) for line in out.splitlines()) <= 80
    proc = wmrid("fleet-report", str(table), "-o", str(tmp_path / "r.json"))  # the page: test_html_report_...
    assert proc.returncode == 0
    assert json.loads((tmp_path / "r.json").read_text())["table"] == str(table)
    assert_clean_error(wmrid("fleet-report", str(table), "-o", str(tmp_path / "r.json")), 2, "exists")
    assert_clean_error(wmrid("fleet-report", str(table), "-o", str(tmp_path / "r.pdf")), 2, ".html, .md or .json")
    assert_clean_error(wmrid("fleet-report", str(tmp_path / "none.parquet")), 2, "no such fleet table")
    (tmp_path / "x.parquet").write_text("no")
    assert_clean_error(wmrid("fleet-report", str(tmp_path / "x.parquet")), 2, "not a Parquet fleet table")
    assert_clean_error(wmrid("fleet-report", str(table), "--alpha", "0.5"), 2, "--alpha", "[1e-09, 0.2]")
    assert_clean_error(wmrid("fleet-report", str(table), "--baseline", "3"), 2, "--baseline", ">= 5")


def test_a_log_identified_twice_counts_once_and_report_robot_gives_the_payload(rows):
    # the same content under two options keys (resume with other options keeps both rows): one log for the review;
    # rows without a robot file get --robot's r and b for the payload
    twice = [dict(r, robot=None) for r in rows] + [dict(r, robot=None, options_key="other") for r in rows]
    rep = fleet_report(twice, robot="paper", figures=False)
    robots = _by_id(rep)
    assert {rid for rid, rv in robots.items() if rv.flagged} == {"R02", "R05", "R08"}
    assert all(len(rv.rows) == 40 for rv in robots.values())
    assert any("left out: each log counts once" in s for s in rep.review.statements)
    assert robots["R05"].payload["mass"][0] == pytest.approx(10.0, abs=3 * robots["R05"].payload["mass"][1])


def test_robots_with_too_few_logs_are_said_not_tested():
    rep = fleet_report(synthetic_rows(6, 8), figures=False)
    assert all(not rv.flagged for rv in rep.review.robots)
    assert all(any("too few" in f for f in rv.findings) for rv in rep.review.robots)


@pytest.mark.slow(reason="simulates and identifies 192 logs of 20 s, about 40 s")
def test_a_simulated_fleet_end_to_end(tmp_path):
    # wmrid's simulator, then each log identified as a fleet task does (identify_entry, in this process), then the
    # review: the right-wheel drift of robot 2 (+4 %/day from day 14) and the 10 kg payload of robot 4 (from day 22)
    # are flagged and dated, nothing else is
    from wmrid.fleets.run import plan
    from wmrid.fleets.table import entries_from_paths
    from wmrid.fleets.worker import identify_entry

    # 20 s logs: friction to about 1.5 % per log (8 s logs scatter by 6 %, and a 4 %/day drift then takes 9 days)
    write_fleet(tmp_path, robots=6, days=32, duration=20.0, drift={1: ("right", 0.04, 14)},
                payload={3: (10.0, 0.05, -0.03, 22)})  # fmt: skip
    specs = plan(entries_from_paths([str(tmp_path)]), {}, "paper", fit=False)
    rows = [identify_entry(s) for s in specs]
    assert all(r["error"] is None for r in rows)
    rep = fleet_report(rows, robot="paper", figures=False)
    robots = _by_id(rep)
    assert {rid for rid, rv in robots.items() if rv.flagged} == {"R02", "R04"}
    wear = robots["R02"].history.changes[0]
    assert robots["R02"].flags == ["wheel wear? (right)"]
    assert wear.alarm - 14 <= 5
    step = robots["R04"].history.changes[0]
    assert step.onset == step.alarm == 22
    assert robots["R04"].time_of(step.onset) == START + dt.timedelta(days=22)
    mass, std = robots["R04"].payload["mass"]
    assert abs(mass - 10.0) <= max(3 * std, 0.05 * 10.0)
    assert np.isfinite(std)


# ---- each wheel's friction at its typical speed (the multibody prototype's case: Fv and Fd trade off per log)


def test_wear_hidden_by_the_fv_fd_trade_is_found_through_the_friction_at_typical_speed():
    """Fv and Fd scatter by 15 % from log to log against each other while their sum at 4 rad/s scatters by 1 %:
    a +1.5 %/day wear of R02's right wheel is flagged through Fw1 within 8 days, and only it; the same rows without
    the speeds (a schema-1 table) hide it: no flag at all."""
    from wmrid.fleets.table import ADDED_IN_2

    rows = synthetic_rows(8, 40, changes={1: _wear(15, 0.015)}, trade=True, seed=11)
    rep = fleet_report(rows, robot="paper", figures=False)
    robots = _by_id(rep)
    assert {rid for rid, rv in robots.items() if rv.flagged} == {"R02"}
    r02 = robots["R02"]
    assert r02.flags == ["wheel wear? (right)"]
    change = r02.history.changes[0]
    assert "Fw1" in change.parameters
    assert 15 <= change.onset <= 18
    assert change.alarm - 15 <= 8
    assert r02.wheel_friction["Fw1"][0] == pytest.approx(4.0, rel=0.02)  # the median of the logs' mean speeds
    assert "Fw1 (the right wheel's friction at 4" in r02.findings[0]
    blind = [{**r, **dict.fromkeys(ADDED_IN_2)} for r in rows]
    assert not any(rv.flagged for rv in fleet_report(blind, robot="paper", figures=False).review.robots)


def test_the_friction_at_typical_speed_is_computed_as_stated():
    """Fw = Fd + omega Fv per log, omega the median of the first logs' mean speeds; its std is the linear
    combination's, from the two std and their correlation (here against a 2x2 covariance by numpy)."""
    rows = synthetic_rows(1, 12, trade=True, seed=2)
    rv = fleet_report(rows, figures=False).review.robots[0]
    omega, value, std = rv.wheel_friction["Fw2"]
    assert omega == float(np.median([r["speed_l"] for r in rows[:10]]))
    for r, v, s in zip(rows, value, std, strict=True):
        assert v == pytest.approx(r["Fd2"] + omega * r["Fv2"], rel=1e-15)
        cov = np.array([[r["Fv2_std"] ** 2, r["Fv2_Fd2_corr"] * r["Fv2_std"] * r["Fd2_std"]],
                        [r["Fv2_Fd2_corr"] * r["Fv2_std"] * r["Fd2_std"], r["Fd2_std"] ** 2]])  # fmt: skip
        weights = np.array([omega, 1.0])
        assert s == pytest.approx(np.sqrt(weights @ cov @ weights), rel=1e-12)


def test_no_false_flags_with_the_friction_at_typical_speed_watched():
    # 30 fleets x 10 unchanged robots with the multibody-like trade and Fw watched (10 parameters): expected false
    # flags 0.3 + 0.03, and more than 3 would reject the stated rate (Poisson(0.33) > 3: p < 5e-4)
    flags = 0
    for seed in range(30):
        rep = fleet_report(synthetic_rows(10, 30, seed=500 + seed, trade=True), figures=False)
        assert all("Fw1" in rv.wheel_friction for rv in rep.review.robots)
        flags += sum(rv.flagged for rv in rep.review.robots)
    assert flags <= 3


def test_the_robot_figure_shows_the_friction_at_typical_speed():
    from wmrid.fleets.figures import build_robot_figure

    rows = synthetic_rows(2, 20, changes={1: _wear(8, 0.02)}, trade=True, seed=4)
    robots = _by_id(fleet_report(rows, figures=False))
    titles = [ax.title for ax in build_robot_figure(robots["R02"]).visible]
    assert len(titles) == 10
    assert re.fullmatch(r"Fw1 at (3\.9\d|4\.0\d) rad/s \(N m\)", titles[4]), titles
    assert re.fullmatch(r"Fw2 at (3\.9\d|4\.0\d) rad/s \(N m\)", titles[9]), titles
    blind = [{**r, "speed_r": None, "speed_l": None} for r in rows]
    assert len(build_robot_figure(_by_id(fleet_report(blind, figures=False))["R02"]).visible) == 8


def test_the_robot_figure_draws_bands_dates_and_the_change(report):
    """R02 (right-wheel wear from day 15): ten panels on a date axis, its changed parameters' titles in red, each
    log's band and estimate, the onset dotted and the first flag red; the drawing read back from its SVG."""
    from wmrid.fleets.figures import build_robot_figure

    rv = _by_id(report)["R02"]
    fig = build_robot_figure(rv)
    changed = {ax.title.split()[0] for ax in fig.visible if ax.title_color == "C3"}
    assert changed == {"Fv1", "Fd1"}
    root = svgutil.parse(fig.to_svg())
    drawn = svgutil.panels(root)
    assert len(drawn) == 8
    for panel in drawn:
        inside = svgutil.data(panel)
        assert len(inside.findall(f"{svgutil.NS}polygon")) == 1  # the ±2σ band
        assert len(svgutil.polylines(inside)) == 1  # the estimates, log to log
        rules = [p for p in inside.iter(f"{svgutil.NS}path") if p.get("d", "").count("V") == 1]
        assert {(p.get("stroke"), p.get("stroke-dasharray") is not None) for p in rules} == {
            ("#4c4c4c", True), ("#d62728", False)
        }  # fmt: skip
    labels = [label for panel in drawn[4:] for label in svgutil.tick_labels(panel, "x")]
    assert labels
    assert all(re.fullmatch(r"2026-\d\d(-\d\d)?", label) for label in labels), labels
    assert all(not svgutil.tick_labels(panel, "x") for panel in drawn[:4])  # one date axis per column


@pytest.mark.parametrize("start", [dt.datetime(1, 1, 1), dt.datetime(9999, 12, 1)], ids=["year 1", "year 9999"])
def test_the_robot_figure_on_forged_dates(start):
    from wmrid.fleets.figures import build_robot_figure

    rows = [dict(r, start_time=start + dt.timedelta(days=i // 2)) for i, r in enumerate(synthetic_rows(2, 20))]
    rv = _by_id(fleet_report(rows, figures=False))["R01"]
    drawn = svgutil.panels(svgutil.parse(build_robot_figure(rv).to_svg()))
    labels = svgutil.tick_labels(drawn[-1], "x")
    assert labels
    assert all(label.startswith(f"{start.year:04d}") for label in labels), labels


def test_the_evidence_figure_ranks_on_a_log_axis_and_escapes_names():
    from wmrid.fleets.figures import build_evidence_figure

    rows = synthetic_rows(3, 20, changes={1: _wear(5, 0.05)})
    for r in rows:
        r["robot_id"] = {"R01": "R<1>", "R02": "R&2", "R03": 'R"3'}[r["robot_id"]]
    review = fleet_report(rows, figures=False).review
    root = svgutil.parse(build_evidence_figure(review).to_svg())
    (panel,) = svgutil.panels(root)
    assert svgutil.tick_labels(panel, "y")[::-1] == [rv.robot_id for rv in review.robots]  # ranked, first on top
    assert "1" in svgutil.tick_labels(panel, "x") or "10⁰" in svgutil.tick_labels(panel, "x")  # the flag line
    bars = [r for r in svgutil.data(panel).findall(f"{svgutil.NS}rect") if r.get("fill") in ("#d62728", "#1f77b4")]
    assert [b.get("fill") == "#d62728" for b in bars][::-1] == [rv.flagged for rv in review.robots]
    assert any(rv.flagged for rv in review.robots)


def test_a_fleet_row_carries_the_mean_wheel_speeds_and_the_friction_correlations(tmp_path):
    """identify_entry's speed_r / speed_l are the log's mean |wheel speed| (the log read again here, by read_log),
    and the correlations those of the identification's own covariance (wmrid.identify, its JSON)."""
    import wmrid
    from wmrid.fleets.run import plan
    from wmrid.fleets.table import entries_from_paths
    from wmrid.fleets.worker import identify_entry

    (path,) = write_fleet(tmp_path, robots=1, days=1, duration=6.0)
    (spec,) = plan(entries_from_paths([str(tmp_path)]), {}, "paper", fit=False)
    row = identify_entry(spec)
    assert row["error"] is None
    log = wmrid.read_log(str(path))
    assert row["speed_r"] == pytest.approx(np.abs(log.eta[:, 0]).mean(), rel=1e-12)
    assert row["speed_l"] == pytest.approx(np.abs(log.eta[:, 1]).mean(), rel=1e-12)
    cov = np.array(wmrid.identify(str(path), robot="paper").to_dict()["estimate"]["covariance"], dtype=float)
    for (v, d), name in (((4, 6), "Fv1_Fd1_corr"), ((5, 7), "Fv2_Fd2_corr")):
        assert row[name] == pytest.approx(cov[v, d] / np.sqrt(cov[v, v] * cov[d, d]), rel=1e-9)
        assert -1 <= row[name] <= 1


def test_each_robot_states_the_smallest_changes_it_would_flag(rows, tmp_path):
    """Under every tested robot: the step of each inertial parameter and the friction rise over 10 logs flagged at
    least half the time, from its first 10 logs' scatter (detectable(h) sd, and no less than twice the median std),
    relative to their mean; in the page, the Markdown and the JSON."""
    from wmrid.fleets.changes import detectable

    rep = fleet_report(rows, robot="paper", figures=False)
    rv = _by_id(rep)["R01"]
    h = rv.history.threshold
    for name in ("M11", "Vc", "Fd2"):
        base = np.array([r[name] for r in rv.rows[:10]])
        floor = 2 * np.median([r[f"{name}_std"] for r in rv.rows[:10]])
        expect_step = max(detectable(h, 10, 1, "step") * base.std(ddof=1), floor) / abs(base.mean())
        expect_ramp = max(detectable(h, 10, 10, "ramp") * base.std(ddof=1), floor) / abs(base.mean())
        assert rv.sensitivity["step"][name] == pytest.approx(expect_step, rel=1e-12)
        assert rv.sensitivity["ramp"][name] == pytest.approx(expect_ramp, rel=1e-12)
    assert rv.sensitivity_text.startswith("smallest changes flagged at least half the time: a step on its first log")
    assert f"M11 {100 * rv.sensitivity['step']['M11']:.2g} %" in rv.sensitivity_text
    write_fleet_report(rep, tmp_path / "r.md")
    write_fleet_report(rep, tmp_path / "r.json")
    assert rv.sensitivity_text in (tmp_path / "r.md").read_text()
    data = json.loads((tmp_path / "r.json").read_text())
    r01 = next(r for r in data["robots"] if r["robot_id"] == "R01")
    assert r01["sensitivity"]["ramp_logs"] == 10
    assert r01["sensitivity"]["step"]["M11"] == pytest.approx(rv.sensitivity["step"]["M11"])
    assert any(s.startswith("Sensitivity:") for s in data["statements"])


def test_figure_units_are_the_models():
    """The fleet figures' panel units come from the model's units table (they said Vc "kg m" and Fv "N m s")."""
    from wmrid.fleets.figures import UNITS
    from wmrid.model.dynamics import THETA0_UNITS

    assert UNITS["Vc"] == "kg m²"
    assert UNITS["Fv1"] == THETA0_UNITS["Fv1"] == "N m s/rad"
    assert UNITS["M11"] == "kg m²"


def test_a_row_identified_with_a_controller_rate_keeps_its_fit(tmp_path):
    """The fit column is the model's simulated speeds on its own log, also for a row with a controller rate (the
    predictor holds each logged effort over its step; only the command line refuses --validate with the rate)."""
    import wmrid
    from wmrid.fleets.run import plan
    from wmrid.fleets.table import entries_from_paths
    from wmrid.fleets.worker import identify_entry

    log = tmp_path / "R1_2026-01-01.csv"
    wmrid.write_simulation(wmrid.simulate("paper", duration=8.0, rate=200.0), log)
    (spec,) = plan(entries_from_paths([str(log)]), {"control_rate": 1000.0}, "paper", fit=True)
    row = identify_entry(spec)
    assert row["error"] is None
    assert row["fit_r"] > 95


def test_a_row_identified_with_payload_carries_the_payload_as_identify_gives_it(tmp_path):
    """``wmrid fleet --payload`` (the run-wide option ``payload``): the row's payload columns are identify's payload
    estimate on the same log, bit for bit; a row without it has them null."""
    import wmrid
    from wmrid.fleets.run import plan
    from wmrid.fleets.table import ADDED_IN_3, entries_from_paths
    from wmrid.fleets.worker import identify_entry

    log = tmp_path / "R1_2026-01-01.csv"
    carried = wmrid.Payload(mass=20.0, x=0.1, y=-0.05, inertia=0.4)
    wmrid.write_simulation(wmrid.simulate("paper", duration=20.0, rate=200.0, payload=carried), log)
    (spec,) = plan(entries_from_paths([str(log)]), {"payload": True}, "paper", fit=False)
    row = identify_entry(spec)
    assert row["error"] is None
    expected = wmrid.identify(str(log), robot="paper", observer=wmrid.ObserverOptions(payload=True)).payload
    assert expected is not None
    for name, (value, std) in expected.items():
        assert (row[f"payload_{name}"], row[f"payload_{name}_std"]) == (value, std)
    assert row["payload_mass"] == pytest.approx(carried.mass, rel=0.1)
    (plain,) = plan(entries_from_paths([str(log)]), {}, "paper", fit=False)
    assert all(identify_entry(plain)[column] is None for column in ADDED_IN_3)


def test_a_payload_without_a_robot_is_one_error_before_any_worker(tmp_path):
    """``wmrid fleet --payload`` with no --robot and no robot column: one line, exit 2, no table (every row failed
    with the same error before)."""
    from cliutil import assert_clean_error, wmrid as run

    import wmrid

    log = tmp_path / "R1_2026-01-01.csv"
    wmrid.write_simulation(wmrid.simulate("paper", duration=2.0, rate=200.0), log)
    out = tmp_path / "t.parquet"
    assert_clean_error(run("fleet", str(log), "--payload", "-o", str(out)), 2, "--payload", "--robot")
    assert not out.exists()
