"""wmrid report: HTML (self-contained), Markdown and JSON reports from a log or a saved result."""

from __future__ import annotations

import hashlib
import html
import json
import re
import subprocess

import cliutil
from cliutil import text
from locations import ROOT_DIR

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.parquet"
TRUTH = ROOT / "sample_logs" / "paper_sinusoid.parquet.truth.json"


def wmrid(*args: str, stdin: bytes | None = None) -> subprocess.CompletedProcess:
    """``wmrid ARGS`` in this process, 200 columns wide."""
    return cliutil.wmrid(*args, stdin=stdin, columns="200")


def test_html_report_from_a_log_is_self_contained_with_tables_and_figures(tmp_path):
    out = tmp_path / "r.html"
    res = tmp_path / "res.csv"
    proc = wmrid(
        "report", str(SAMPLE), "--robot", "paper", "--truth", str(TRUTH), "-o", str(out), "--residuals", str(res)
    )
    assert proc.returncode == 0, proc.stderr.decode()
    page = out.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>")
    assert "paper Table 3" in page
    assert "paper Table 2" in page
    assert "error %" in page
    # Five figure kinds: overview, path, estimates (+ errors with truth), residuals, excitation.
    figures = re.findall(r"<figure><figcaption>(.*?)(?: <span|</figcaption>)", page)
    assert figures == [
        "Base parameters over time", "Measured and predicted wheel speeds", "Parameter correlations",
        "Wheel efforts and speeds (paper Fig. 6)", "Path (paper Fig. 5)", "Intermediate parameters over time",
        "Estimation errors over time (paper Fig. 7)", "Prediction errors", "Excitation: λ_min(Γ) over time",
    ]  # fmt: skip
    assert page.count("<svg") == len(figures)
    assert_self_contained(page)
    assert "<text" in page  # figure text is text (searchable, selectable), not glyph outlines
    lines = res.read_text().splitlines()
    assert lines[0] == "t,tau_res_r,tau_res_l,e_r,e_l,lambda_min"
    assert len(lines) == 40001 + 1  # every sample of the log
    assert "fit tau_r" in page
    # the reproducibility block: version, time, the command as typed, the input's size and SHA-256
    block = page[page.index("id='reproducibility'") :]
    assert wmrid_version() in block
    assert re.search(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", block)
    assert f"wmrid report {SAMPLE} --robot paper --truth {TRUTH} -o {out}" in html.unescape(block)
    assert hashlib.sha256(SAMPLE.read_bytes()).hexdigest() in block
    assert f"{SAMPLE.stat().st_size:,}" in block
    # the base table: estimate, std, a 95 % interval that holds the estimate, inside a box that scrolls sideways
    assert "<div class='scroll'><table><thead><tr><th>parameter</th><th>unit</th><th>estimate</th><th>std</th>" \
        "<th>95 % interval</th>" in page  # fmt: skip
    # cells never break a number; headers may wrap, so that the table with truth fits 1280 px (issue 33)
    assert "th,td{padding:0.25em 0.55em;border-bottom:1px solid #ddd;text-align:right;white-space:nowrap}" in page
    assert "th{white-space:normal;vertical-align:bottom}" in page
    # the path is in the page header, not in the figures
    header = page[page.index("<header>") : page.index("</header>")]
    assert str(SAMPLE) in header
    assert str(SAMPLE) not in "".join(re.findall(r"<svg.*?</svg>", page, flags=re.S))


def assert_self_contained(page: str) -> None:
    """Nothing is fetched: no script, stylesheet link, remote image or font, or CSS import (SVG namespace URIs are
    names, not fetched)."""
    for external in ('src="http', "src='http", 'href="http', "href='http", "url(http", "url('http", "<script",
                     "<link ", "@import", "<iframe", "<object", "<embed"):  # fmt: skip
        assert external not in page, external


def wmrid_version() -> str:
    from wmrid import __version__

    return __version__


def test_a_urdf_robots_unknown_friction_is_a_dash_and_no_payload_is_said(tmp_path):
    """A URDF gives no friction: its CAD friction shows as "—" (not 0, which made Δ/std +185592.1).  --payload on
    a log with no payload says so (the sample against the paper robot it was simulated with: the mass estimate is
    -2e-5 kg, within its error of zero).  (JSON reports: the same tables as HTML, without the figures' time.)"""
    urdf = ROOT / "tests" / "data" / "paper_robot.urdf"
    out = tmp_path / "r.json"
    proc = wmrid("report", str(SAMPLE), "--robot", str(urdf), "--gear-ratio", "30", "-o", str(out))
    assert proc.returncode == 0, proc.stderr.decode()
    base = json.loads(out.read_text())["base"]
    rows = {row[0]: row for row in base["rows"]}
    cad, z = base["header"].index("CAD"), base["header"].index("(est − CAD)/std")
    for name in ("Fv1", "Fv2", "Fd1", "Fd2"):
        assert rows[name][cad] == "—", rows[name]
        assert rows[name][z] == "—", rows[name]
    assert rows["m11"][cad] != "—"
    table = text(wmrid("identify", str(SAMPLE), "--robot", str(urdf), "--gear-ratio", "30", "--format", "table"))
    fv1 = next(line for line in table.stdout.splitlines() if line.strip().startswith("Fv1"))
    assert fv1.split()[-2:] == ["—", "—"]
    unloaded = text(wmrid("identify", str(SAMPLE), "--robot", "paper", "--payload", "--format", "table"))
    assert "no payload detected: the mass estimate" in unloaded.stdout
    assert wmrid("report", str(SAMPLE), "--robot", "paper", "--payload", "-o", str(out), "--force").returncode == 0
    assert json.loads(out.read_text())["payload"]["statement"].startswith("No payload detected: the mass estimate")


def test_the_summary_box_says_the_verdict_first_and_keeps_command_options_whole(tmp_path):
    """A result whose method is not the observer's (ME169: the closed-loop check reported IDIM) heads its summary box
    with the verdict, then the method note (in the terminal the note comes first); a command-line option in the
    report's prose is never broken after its hyphen (Chromium broke "(--format" into "(--" and "format" at 1280 px)."""
    golden = json.loads((ROOT / "tests" / "data" / "golden" / "me169_wheel.json").read_text())["result"]
    saved = tmp_path / "run.json"
    saved.write_text(json.dumps(golden))
    out = tmp_path / "r.html"
    assert wmrid("report", str(saved), "-o", str(out)).returncode == 0
    page = out.read_text(encoding="utf-8")
    box = page[page.index("<section class='summary") : page.index("</section>")]
    headline = html.unescape(re.sub("<[^>]+>", "", re.search("<p class='headline'>(.*?)</p>", box).group(1)))
    assert headline == golden["verdict"]["summary"]
    first = re.search("<li>(.*?)</li>", box).group(1)
    assert html.unescape(re.sub("<[^>]+>", "", first)).startswith("Method: IDIM, not the observer")
    assert "<span class='nb'>--method</span> observer" in box
    assert "(<span class='nb'>--format</span> json <span class='nb'>-o</span> run.json)" in box
    assert ".nb{white-space:nowrap}" in page
    assert "PWM-based" in page  # a hyphen inside a word is not an option
