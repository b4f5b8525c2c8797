"""wmrid report: HTML (self-contained), Markdown and JSON reports from a log or a saved result."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import cliutil
import pytest

ROOT = Path(__file__).resolve().parents[1]
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
    assert page.count("<figure>") >= 6
    assert page.count("<svg") >= 6
    for external in ('src="http', 'href="http', "url(http", "<script", "<link "):
        assert external not in page  # nothing is fetched (SVG namespace URIs are names, not fetched)
    lines = res.read_text().splitlines()
    assert lines[0] == "t,tau_res_r,tau_res_l,e_r,e_l,lambda_min"
    assert len(lines) == 40001 + 1  # every sample of the log
    assert "fit tau_r" in page


def test_report_from_a_saved_json_result_through_a_pipe(tmp_path):
    identified = wmrid("identify", str(SAMPLE), "--robot", "paper", "--format", "json")
    assert identified.returncode == 0
    out = tmp_path / "r.md"
    proc = wmrid("report", "-", "-o", str(out), "--truth", str(TRUTH), stdin=identified.stdout)
    assert proc.returncode == 0, proc.stderr.decode()
    text = out.read_text()
    assert "| m11 |" in text
    assert "data:image/png;base64," in text  # figures from the history the JSON carries
    as_json = tmp_path / "r.json"
    assert wmrid("report", "-", "-o", str(as_json), stdin=identified.stdout).returncode == 0
    data = json.loads(as_json.read_text())
    assert [row[0] for row in data["base"]["rows"]][:3] == ["m11", "m12", "m22"]


def test_report_errors_are_one_line(tmp_path):
    bad = wmrid("report", str(SAMPLE), "-o", str(tmp_path / "r.pdf"))
    assert bad.returncode == 2
    assert ".html, .md or .json" in bad.stderr.decode()
    not_result = tmp_path / "x.json"
    not_result.write_text('{"a": 1}')
    bad = wmrid("report", str(not_result))
    assert bad.returncode == 2
    assert "not an identify result" in bad.stderr.decode()
    assert "Traceback" not in bad.stderr.decode()


@pytest.mark.parametrize("flag", ["--payload"])
def test_report_terminal_tables_with_payload(flag):
    proc = wmrid("report", str(SAMPLE), "--robot", "paper", flag)
    assert proc.returncode == 0, proc.stderr.decode()
    text = proc.stdout.decode()
    assert "Base parameters" in text
    assert "Payload" in text
