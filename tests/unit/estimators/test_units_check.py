"""Unit mistakes are said before any number (issue 28, item 1): wmrid.estimators.plausibility and the verdict.

The scaling law the check rests on (speeds logged s times too large give M / s, Vc / s^2, Fv / s; a time column q
times too large gives q M) is checked first against wmrid's own estimates of a rescaled log, a closed form;
then the bundled sample with its speeds in rpm and its time in milliseconds, with and without a robot file, through
the library and the command line; then the pure functions on constructed estimates.  The MuJoCo prototype's log
(a multibody simulation, not wmrid's reduced model) is checked in a slow test.
"""

from __future__ import annotations

import html
import math
import re
from dataclasses import replace

import numpy as np
import pytest
from locations import ROOT_DIR

import wmrid
from tests.cliutil import text, wmrid as cli
from wmrid.estimators.plausibility import robot_findings, signal_findings

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"
RPM = 60.0 / (2.0 * math.pi)


@pytest.fixture(scope="module")
def sample():
    log = wmrid.read_log(SAMPLE)
    keep = log.t <= 12.0  # 12 s: enough for every parameter to better than 1e-4, a third of the time
    return replace(log, t=log.t[keep], eta=log.eta[keep], tau=log.tau[keep])


@pytest.fixture(scope="module")
def clean(sample):
    return wmrid.identify(sample, "paper")


@pytest.fixture(scope="module")
def in_rpm(sample):
    return replace(sample, eta=sample.eta * RPM)


@pytest.fixture(scope="module")
def in_ms(sample):
    return replace(sample, t=sample.t * 1000.0)


def test_the_scaling_law_holds_on_the_estimates(clean, in_rpm, sample):
    """M' = M/s, Vc' = Vc/s^2, Fv' = Fv/s, Fd' = Fd for speeds s times too large; M' = q M for times q times too
    large.  Speeds: to 1e-4 relative (the estimates of a noise-free log are exact to about 1e-6, and rescaling the
    speeds leaves the observer's filters as they are).  Time: to 1e-3, because the observer's gain k is in 1/s, so on
    a clock twice as slow its filter acts as k/2, and the noise-free sample's estimates move by up to 1.0e-4 (Fv1)
    from one filter to another."""
    rpm = wmrid.identify(in_rpm, "paper")
    slow = wmrid.identify(replace(sample, t=sample.t * 2.0), "paper")
    p, q, r = clean.parameters, rpm.parameters, slow.parameters
    for name, exponent in (("M11", -1), ("M22", -1), ("M12", -1), ("Vc", -2), ("Fv1", -1), ("Fv2", -1), ("Fd1", 0)):
        assert q[name][0] / p[name][0] == pytest.approx(RPM**exponent, rel=1e-4), name
    for name, factor in (("M11", 2.0), ("M22", 2.0), ("Vc", 1.0), ("Fv1", 1.0), ("Fd2", 1.0)):
        assert r[name][0] / p[name][0] == pytest.approx(factor, rel=1e-3), name


def test_a_clean_log_has_no_finding_and_no_flag(clean):
    units = clean.diagnostics.units
    assert units.findings == ()
    assert units.doubt is False
    assert units.robot.rms_factor == pytest.approx(1.0, abs=1e-3)  # the sample's truth is the CAD set
    assert clean.diagnostics.flagged == ()
    assert clean.verdict.summary == "This log determines the inertia, Coriolis coefficient and friction."


def test_rpm_with_a_robot_file_is_named_and_flags_everything(in_rpm):
    result = wmrid.identify(in_rpm, "paper")
    units = result.diagnostics.units
    assert units.doubt is True
    assert units.findings[0].fix == "--speed-unit rpm"
    assert result.warnings[0].startswith("unit check: ")
    assert "--speed-unit rpm" in result.warnings[0]
    assert result.diagnostics.flagged == tuple(result.parameters)
    assert result.verdict.summary.startswith("Do not use these numbers:")
    assert all(g.status == "in doubt" for g in result.verdict.groups)


def test_rpm_without_a_robot_file_is_not_silent(in_rpm):
    """Without a robot nothing says what a wheel's speed should be; 72 'rad/s' is fast for a wheel, and said so."""
    result = wmrid.identify(in_rpm)
    assert [w for w in result.warnings if w.startswith("unit check: ") and "--speed-unit rpm" in w]
    assert re.search(r"speeds read as rad/s \(up to 7\d", result.verdict.units)


@pytest.mark.parametrize("robot", ["paper", None])
def test_milliseconds_are_named_with_and_without_a_robot_file(in_ms, robot):
    result = wmrid.identify(in_ms, robot)
    units = result.diagnostics.units
    assert units.doubt is True
    assert units.findings[0].fix == "--time-unit ms"
    assert "would make it 1000 Hz over 12 s" in units.findings[0].text
    assert result.verdict.summary.startswith("Do not use these numbers:")


def test_whole_number_efforts_are_taken_for_pwm(sample):
    pwm = replace(sample, tau=np.round(sample.tau * 15.0))
    result = wmrid.identify(pwm)
    assert result.diagnostics.units.findings[0].fix == "--effort pwm"
    assert "PWM counts" in result.verdict.summary


def test_the_command_line_says_it_first(tmp_path, in_rpm):
    """The table's first line is the verdict naming the flag; JSON has ``verdict`` before ``parameters``."""
    path = tmp_path / "rpm.csv"
    rows = np.column_stack([in_rpm.t, in_rpm.eta, in_rpm.tau])
    np.savetxt(path, rows, delimiter=",", header="t,eta_r,eta_l,tau_r,tau_l", comments="")
    out = text(cli("identify", str(path), "--robot", "paper", "--format", "table", "--no-history"))
    assert out.returncode == 0, out.stderr
    first = out.stdout.lstrip().splitlines()[0]
    assert first.startswith("verdict: Do not use these numbers:")
    assert "--speed-unit rpm" in " ".join(out.stdout.split())
    fixed = text(cli("identify", str(path), "--robot", "paper", "--speed-unit", "rpm", "--format", "table"))
    assert fixed.stdout.lstrip().startswith("verdict: This log determines the inertia")


# ---- the pure functions


def named(m11, m22, vc, fv=0.0, fd=0.0, std=1e-3):
    return {"M11": (m11, std * m11), "M22": (m22, std * m22), "Vc": (vc, std * abs(vc) if vc else 1.0),
            "Fv1": (fv, std * fv if fv else 1.0), "Fd1": (fd, std * fd if fd else 1.0)}  # fmt: skip


REF = {"M11": 1.2, "M22": 1.3, "Vc": 0.2, "Fv1": 0.05, "Fd1": 0.3}


@pytest.mark.parametrize(
    ("scale", "fix"),
    [
        ((1 / RPM, 1 / RPM**2, 1 / RPM, 1.0), "--speed-unit rpm"),  # speeds in rpm
        ((math.pi / 180, (math.pi / 180) ** 2, math.pi / 180, 1.0), "--speed-unit deg/s"),
        ((1000.0, 1.0, 1.0, 1.0), "--time-unit ms"),
        ((1e6, 1.0, 1.0, 1.0), "--time-unit us"),
        ((1 / 0.05, 1 / 0.05**2, 1 / 0.05, 1.0), "--speed-unit m/s"),  # rim speeds in m/s, r = 5 cm
    ],
)
def test_each_unit_is_told_from_the_others(scale, fix):
    est = named(REF["M11"] * scale[0], REF["M22"] * scale[0] * 1.1, REF["Vc"] * scale[1], REF["Fv1"] * scale[2],
                REF["Fd1"] * scale[3])  # fmt: skip
    findings, _ = robot_findings(est, [("nominal", REF)], 0.05)
    assert findings, "nothing found"
    assert findings[0]["doubt"], findings
    assert findings[0]["fix"] == fix, findings[0]["text"]


def test_a_uniform_scale_is_said_but_not_taken_for_a_unit():
    """Every parameter 40 times the robot file's: efforts in PWM counts, or a robot 40 times heavier than its file;
    nothing tells them apart, so it is a warning naming both, not a doubt (found by review: a heavy robot identified
    with the light AMR's file was called an effort-unit mistake)."""
    est = named(REF["M11"] * 40, REF["M22"] * 44, REF["Vc"] * 40, REF["Fv1"] * 40, REF["Fd1"] * 40)
    findings, _ = robot_findings(est, [("nominal", REF)], 0.05)
    assert findings[0]["doubt"] is False
    assert "the robot file does not describe this robot, or the efforts are not in N m" in findings[0]["text"]


def test_efforts_in_other_units_still_show_a_speed_unit_through_ratios():
    """Efforts as PWM (any scale) with speeds in rpm: Vc/M and Fv/M still show the speed unit (found by review)."""
    pwm, s = 30.0, RPM
    est = named(REF["M11"] * pwm / s, REF["M22"] * pwm / s, REF["Vc"] * pwm / s**2, REF["Fv1"] * pwm / s,
                REF["Fd1"] * pwm)  # fmt: skip
    findings, _ = robot_findings(est, [("nominal", REF)], 0.05, effort_free=True)
    assert findings[0]["fix"] == "--speed-unit rpm"
    assert findings[0]["doubt"] is True
    clean = named(REF["M11"] * pwm, REF["M22"] * pwm, REF["Vc"] * pwm, REF["Fv1"] * pwm, REF["Fd1"] * pwm)
    assert robot_findings(clean, [("nominal", REF)], 0.05, effort_free=True)[0] == []


def test_a_robot_file_off_by_less_than_twice_is_no_finding():
    est = named(REF["M11"] * 1.6, REF["M22"] * 0.7, REF["Vc"] * 1.8, REF["Fv1"] * 0.6, REF["Fd1"] * 1.5)
    findings, record = robot_findings(est, [("nominal", REF)], 0.05)
    assert findings == []
    assert record["rms_factor"] < 2


def test_far_from_the_robot_file_without_a_unit_is_a_warning_not_a_doubt():
    est = named(REF["M11"] * 30, REF["M22"] * 0.03, REF["Vc"] * 5, REF["Fv1"], REF["Fd1"])
    findings, _ = robot_findings(est, [("nominal", REF)], 0.05)
    assert len(findings) == 1
    assert findings[0]["doubt"] is False
    assert "check the log's units" in findings[0]["text"]


def test_signals_alone():
    base = {"speed_max": [5.0, 5.0], "effort_max": [2.0, 2.0], "effort_whole": False, "rate_hz": 100.0,
            "duration_s": 60.0, "effort_unit": "N m"}  # fmt: skip
    assert signal_findings(base) == []
    assert signal_findings({**base, "rate_hz": 0.001, "duration_s": 6e7})[0]["fix"] == "--time-unit us"
    rpm = signal_findings({**base, "speed_max": [200.0, 5.0]}, r=0.1)[0]  # 20 m/s: rpm 2.1 m/s, deg/s 0.35 m/s
    assert rpm["fix"] == "--speed-unit rpm"
    assert "give --speed-unit deg/s" in rpm["text"]  # both named, the more typical first
    assert signal_findings({**base, "speed_max": [1000.0, 5.0]}, r=0.5)[0]["fix"] == "--speed-unit deg/s"
    amr = signal_findings({**base, "speed_max": [402.0, 5.0]}, r=0.08)[0]  # the review's deg/s AMR log: 32 m/s
    assert amr["doubt"] is True
    assert "give --speed-unit rpm" in amr["text"]
    assert "give --speed-unit deg/s" in amr["text"]
    assert signal_findings({**base, "effort_whole": True, "effort_max": [255.0, 250.0]})[0]["fix"] == "--effort pwm"
    assert signal_findings({**base, "effort_whole": True, "effort_unit": "A", "effort_max": [255.0, 1]}) == []


@pytest.mark.slow
def test_the_multibody_prototype_in_rpm_and_ms():
    """On the MuJoCo prototype's log (a multibody simulation; reversing, sensor noise): rpm with the robot file and ms
    with or without it are named, the log as it is has no finding."""
    run = wmrid.simulate(
        ROOT / "examples" / "small_amr.toml",
        duration=20,
        rate=200,
        engine="mujoco",
        trajectory="reversing",
        noise=wmrid.NoiseSettings(seed=3, eta_std=0.02, tau_std=0.01),
    )
    amr = ROOT / "examples" / "small_amr.toml"
    log = run.log
    assert wmrid.identify(log, amr).diagnostics.units.findings == ()
    rpm = wmrid.identify(replace(log, eta=np.asarray(log.eta) * RPM), amr)
    assert rpm.diagnostics.units.findings[0].fix == "--speed-unit rpm"
    for robot in (amr, None):
        ms = wmrid.identify(replace(log, t=np.asarray(log.t) * 1000.0), robot)
        assert ms.diagnostics.units.findings[0].fix == "--time-unit ms"


def test_the_report_opens_with_the_verdict(in_rpm, clean):
    """Markdown and HTML reports put the verdict first: bold, the groups as a list; in red when it says not to use
    the numbers (issue 28)."""
    from wmrid.reporting.report_html import to_html
    from wmrid.reporting.report_markdown import to_markdown

    doubt = wmrid.report(wmrid.identify(in_rpm, "paper"), figures=False)
    text_md = to_markdown(doubt)
    assert text_md.split("\n\n")[1].startswith("**Verdict:** Do not use these numbers:")
    assert "--speed-unit rpm" in text_md.split("##")[0]
    page = to_html(doubt)
    # the summary box first (issue 33): the verdict, the key numbers, what to do next; red when not to use them
    box = page.split("<section class='summary bad'>")[1].split("</section>")[0]
    assert page.index("<section class='summary bad'>") < page.index("Base parameters (paper Table 3)")
    assert "<p class='headline'>Do not use these numbers:" in box
    assert doubt.next_steps[0].startswith("Check the log's units and columns first")
    assert html.escape(doubt.next_steps[0]) in box
    clean_report = wmrid.report(clean, figures=False)
    good = to_markdown(clean_report)
    assert "**Verdict:** This log determines the inertia, Coriolis coefficient and friction." in good
    assert "- Inertia (M11, M22, M12): determined" in good
    assert [name for name, _ in clean_report.key_numbers[:4]] == ["M11", "M22", "M12", "Vc"]
    assert clean_report.key_numbers[0][1].endswith(" kg m^2")
    assert " ± " in clean_report.key_numbers[0][1]
    assert clean_report.next_steps[-1].startswith("Use the numbers:")
    assert "<section class='summary good'>" in to_html(clean_report)
    assert "**What to do next**" in good
