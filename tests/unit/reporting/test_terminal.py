"""The terminal output of every command: data printed verbatim (no Rich markup interpretation), JSON mode's warning
summary on stderr, and tables that fit 80 columns."""

from __future__ import annotations

import json
import re
import shutil

import pytest
from locations import ROOT_DIR

from tests.cliutil import text, wmrid

ROOT = ROOT_DIR
#: Square brackets as a path may hold them: a closing tag (across a folder and its file), a style, a plain word, an
#: unmatched one.
MARKUP = "logs [bold] run [/red] [motor] x[ ]"


@pytest.fixture(scope="module")
def bracketed(tmp_path_factory):
    """A 6-s noisy simulated log and a model identified from it, with markup-like paths (``MARKUP`` in each)."""
    folder = tmp_path_factory.mktemp("brackets") / "logs [bold] run ["
    folder.mkdir()
    log = folder / "red] [motor] x[ ].csv"
    out = wmrid("simulate", "-o", log, "--duration", "6", "--eta-noise", "0.01", "--tau-noise", "0.01")
    assert out.returncode == 0, text(out).stderr
    model = folder / "red] [motor] x[ ].json"
    out = wmrid("identify", log, "--robot", "paper", "-o", model, "--format", "json")
    assert out.returncode == 0, text(out).stderr
    return log, model


def test_markup_like_names_print_verbatim_in_every_command(bracketed, tmp_path):
    """The issue's "done when": file names and notes holding [, ], [/red] and [bold] print verbatim; before, notes
    lost '[motor]' and a name with '[/red]' ended in 'internal error: MarkupError'."""
    log, model = bracketed
    runs = {
        "identify": ("identify", log, "--robot", "paper", "--format", "table"),
        "inspect": ("inspect", log, "--format", "table"),
        "report": ("report", log, "--robot", "paper"),
        "report -o": ("report", log, "--robot", "paper", "-o", log.with_suffix(".md"), "--force"),
        "compare": ("compare", log, "--robot", "paper", "--methods", "observer,idim", "--format", "table"),
        "monitor": ("monitor", log, "--model", model, "--calibration", "4", "--format", "table"),
        "simulate": ("simulate", "-o", log.with_name("red] [motor] x[ ] sim.csv"), "--duration", "1", "--force"),
    }
    for name, args in runs.items():
        out = text(wmrid(*args, columns="250"))
        assert out.returncode == 0, (name, out.stderr)
        printed = out.stdout + out.stderr
        assert "MarkupError" not in printed, name
        assert MARKUP in printed, (name, printed[:2000])
        assert "\\[" not in printed, name  # no escaping left visible either


def test_warnings_keep_their_brackets(bracketed):
    """A warning that names a [section] of a file keeps it: the note that read '... or a robot  table' reads
    '... or a robot [motor] table' (a log in volts without a torque constant)."""
    log, _ = bracketed
    out = text(wmrid("identify", log, "--robot", "paper", "--effort", "current", "--format", "table"))
    assert "[motor]" in out.stdout + out.stderr, out.stdout + out.stderr


def test_no_colour_codes_when_no_color_is_set(bracketed, monkeypatch):
    """NO_COLOR: not one escape sequence, even when Rich is told it writes to a terminal."""
    log, _ = bracketed
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("FORCE_COLOR", "1")
    out = text(wmrid("identify", log, "--robot", "paper", "--format", "table", "--effort", "current"))
    assert not colours(out.stdout + out.stderr)
    monkeypatch.delenv("NO_COLOR")
    out = text(wmrid("identify", log, "--robot", "paper", "--format", "table", "--effort", "current"))
    assert "33" in colours(out.stdout + out.stderr)  # the warning's yellow, so the check above means something


def colours(printed: str) -> set[str]:
    """The colour codes of the SGR escape sequences in ``printed`` (foreground, background, 256 and true colour;
    bold and italic are not colours, and NO_COLOR leaves them)."""
    codes = set()
    for params in re.findall(r"\x1b\[([0-9;]*)m", printed):
        for code in params.split(";"):
            if code.isdigit() and (30 <= int(code) <= 49 or 90 <= int(code) <= 107):
                codes.add(code)
                if code in ("38", "48"):
                    break  # the rest are the colour's own numbers
    return codes


def test_copy_is_left_alone(bracketed, tmp_path):
    """(Housekeeping) the bracketed log is read, never written: a copy compares equal after every command."""
    log, _ = bracketed
    before = log.read_bytes()
    shutil.copy(log, tmp_path / "copy.csv")
    wmrid("inspect", log, "--format", "json")
    assert log.read_bytes() == before
    assert json.loads(wmrid("inspect", log, "--format", "json").stdout)["source"] == str(log)


def test_json_mode_summarises_the_warnings_on_stderr(bracketed, tmp_path):
    """--format json (and -o -): the JSON on stdout as before, and one line on stderr with the number of warnings
    and the first, so that a script reading m11 learns the log may not support it.  No warnings, no line."""
    log, _ = bracketed
    for args in (("--format", "json"), ("-o", "-")):
        out = text(wmrid("identify", log, "--robot", "paper", "--effort", "current", *args))
        result = json.loads(out.stdout)
        lines = out.stderr.splitlines()
        assert len(lines) == 1, out.stderr
        count = len(result["warnings"])
        assert count >= 1
        assert lines[0].startswith(f"wmrid: {count} warning")
        assert " ".join(result["warnings"][0].split())[:100] in lines[0]
    clean = text(wmrid("identify", ROOT / "sample_logs" / "paper_sinusoid.csv", "--format", "json"))
    assert json.loads(clean.stdout)["warnings"] == []
    assert clean.stderr == ""
    compared = text(wmrid("compare", log, "--robot", "paper", "--methods", "observer,idim", "--effort", "current",
                          "--format", "json"))  # fmt: skip
    n = sum(len(m["warnings"]) for m in json.loads(compared.stdout)["methods"].values())
    assert compared.stderr.startswith(f"wmrid: {n} warning"), compared.stderr


def test_no_history_leaves_the_history_out_and_nothing_else(bracketed):
    log, _ = bracketed
    full = json.loads(wmrid("identify", log, "--robot", "paper", "--format", "json").stdout)
    lean = json.loads(wmrid("identify", log, "--robot", "paper", "--format", "json", "--no-history").stdout)
    assert "history" in full
    assert "history" not in lean
    for key in set(full) - {"history", "diagnostics", "log"}:
        assert lean[key] == full[key], key


def test_the_old_out_spelling_still_writes_the_mcap_with_a_note(bracketed, tmp_path):
    log, _ = bracketed
    old = text(wmrid("identify", log, "--robot", "paper", "--format", "json", "--no-history",
                     "--out", tmp_path / "old.mcap"))  # fmt: skip
    assert old.returncode == 0, old.stderr
    assert "--out is now --mcap-out" in old.stderr
    new = text(wmrid("identify", log, "--robot", "paper", "--format", "json", "--no-history",
                     "--mcap-out", tmp_path / "new.mcap"))  # fmt: skip
    assert new.returncode == 0, new.stderr
    assert "--out" not in new.stderr
    assert (tmp_path / "old.mcap").stat().st_size == (tmp_path / "new.mcap").stat().st_size


COMMANDS = ("identify", "inspect", "report", "compare", "simulate", "monitor")


@pytest.mark.parametrize("name", COMMANDS)
def test_help_has_panels_an_example_and_verbatim_text(name):
    """Help grouped into panels (the option groups the code defines), an example per command, square brackets in
    help texts shown as written (they are rendered with Rich), nothing cut at 80 columns."""
    out = text(wmrid(name, "--help", columns="80"))
    assert out.returncode == 0, out.stderr
    assert "Examples:" in out.stdout
    assert f"wmrid {name} " in out.stdout.split("Examples:")[1]
    assert "╭─ Options" in out.stdout
    if name in ("identify", "report", "compare"):
        assert "╭─ Method" in out.stdout
        assert "[0.98, 1]" in out.stdout.replace("│", " ").replace("\n", " ").replace("  ", " ")
        # the log's input folded into one line that --help-all unfolds (issue 33)
        assert "Folded: Log input" in " ".join(out.stdout.split())
        assert "╭─ Log input" not in out.stdout
        assert "╭─ Log input" in text(wmrid(name, "--help-all", columns="80")).stdout
    if name == "identify":
        assert "[m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2]" in out.stdout
    assert "…" not in out.stdout, [line for line in out.stdout.splitlines() if "…" in line]


def test_shell_completion_is_on(monkeypatch):
    """``--show-completion`` prints the script for the shell Typer finds among the process's parents (a flag: a word
    after it is not read as the shell).  The shell is said here: a test run not started from a shell (a CI runner, a
    job whose shell has exited) has none, and the script was then refused as "Shell  not supported"."""
    monkeypatch.setattr("typer.completion._get_shell_name", lambda: "bash")
    out = text(wmrid("--show-completion"))
    assert out.returncode == 0, out.stderr
    assert "_WMRID_COMPLETE" in out.stdout


def test_an_impossible_value_is_marked_in_the_table():
    """A value no robot has is marked ✗ (and red) in the table itself, with a legend, not only in the warnings
    below: the sample identified with its efforts' sign flipped has an inverse inertia that is not positive
    definite (m11 < 0), so m11, m12, m22 and the M computed from them are marked, and the friction (within 3 std
    of zero) is not."""
    out = text(wmrid("identify", ROOT / "sample_logs" / "paper_sinusoid.csv", "--flip-effort", "--format", "table",
                     columns="100"))  # fmt: skip
    rows = {line.split()[0]: line for line in out.stdout.splitlines() if line.strip()[:3] in ("Fv1", "M11", "m11")}
    assert "✗" in rows["m11"]
    assert "✗" in rows["M11"]
    assert "✗" not in rows["Fv1"]
    assert "✗ impossible for a physical robot (M11, M12, M22, m11, m12, m22)" in out.stdout


def test_compare_says_what_it_is_doing(bracketed):
    """compare's stages, for the spinner on a terminal: the log, the observer, then each method in turn."""
    import wmrid as api

    log, _ = bracketed
    stages = []
    api.compare(str(log), "paper", methods=["observer", "idim"], stage=stages.append)
    assert stages == ["reading the log", "the observer's run", "observer (1 of 2)", "idim (2 of 2)"]


def test_the_spinner_shows_on_a_terminal_only(monkeypatch):
    """On a terminal stderr the activity line is drawn (and cleared when done); elsewhere nothing is written."""
    import io
    import sys

    from wmrid.cli.helpers import activity

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    for stream, shown in ((Terminal(), True), (io.StringIO(), False)):
        monkeypatch.setattr(sys, "stderr", stream)
        with activity("wmrid compare") as stage:
            stage("idim (2 of 4)")
        assert ("wmrid compare" in stream.getvalue()) == shown
