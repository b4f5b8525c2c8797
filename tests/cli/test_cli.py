"""The real ``wmrid`` command line, run in a subprocess."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cliutil import assert_clean_error, process, text, wmrid
from locations import ROOT_DIR

from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS, Payload

ROOT = ROOT_DIR
SAMPLE_CSV = ROOT / "sample_logs" / "paper_sinusoid.csv"
SAMPLE_PARQUET = ROOT / "sample_logs" / "paper_sinusoid.parquet"
REPORTED = ["m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2"]


def identify_json(*args: str, stdin: bytes | None = None) -> dict:
    proc = wmrid("identify", *args, "--format", "json", stdin=stdin)
    assert proc.returncode == 0, proc.stderr.decode()
    return json.loads(proc.stdout)  # exactly one JSON object on stdout, nothing else


def truth_of(path: Path) -> dict:
    return json.loads(Path(str(path) + ".truth.json").read_text())["parameters"]


def test_identify_sample_log_json_recovers_the_truth():
    out = identify_json(str(SAMPLE_CSV), "--robot", "paper")
    truth = truth_of(SAMPLE_CSV)
    assert list(out["parameters"]) == REPORTED
    for name in REPORTED:
        entry = out["parameters"][name]
        assert isinstance(entry["value"], float), name
        assert isinstance(entry["std"], float), name
        # The paper's worst is 0.234 %; this noise-free log is recovered far better (see docs/explanation/paper.md).
        assert entry["value"] == pytest.approx(truth[name], rel=5e-4), name
    assert {"theta", "diagnostics"} <= out.keys()
    assert out["theta"]["form"]["kind"] == "paper"


def test_identify_without_a_robot_states_its_start_and_still_converges():
    out = identify_json(str(SAMPLE_PARQUET))
    truth = truth_of(SAMPLE_PARQUET)
    for name in REPORTED:
        assert out["parameters"][name]["value"] == pytest.approx(truth[name], rel=5e-4), name
    assert "from the data" in out["settings"]["start"]


def test_identify_reads_standard_input():
    from_file = identify_json(str(SAMPLE_PARQUET), "--robot", "paper")
    from_pipe = identify_json("-", "--robot", "paper", stdin=SAMPLE_PARQUET.read_bytes())
    assert from_pipe["parameters"] == from_file["parameters"]


def test_identify_table_on_request():
    proc = wmrid("identify", str(SAMPLE_CSV), "--robot", "paper", "--format", "table")
    assert proc.returncode == 0, proc.stderr.decode()
    text = proc.stdout.decode()
    for name in REPORTED:
        assert f" {name} " in text
    assert "CAD" in text


def test_identify_writes_json_file_atomically_and_refuses_to_overwrite(tmp_path):
    target = tmp_path / "result.json"
    proc = wmrid("identify", str(SAMPLE_CSV), "--robot", "paper", "--format", "json", "-o", str(target))
    assert proc.returncode == 0, proc.stderr.decode()
    assert json.loads(target.read_text())["parameters"] == json.loads(proc.stdout)["parameters"]
    before = target.read_bytes()
    proc = wmrid("identify", str(SAMPLE_CSV), "-o", str(target))
    assert_clean_error(proc, 2, str(target), "--force")
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.json"]  # no temporary left behind


def test_an_output_that_cannot_be_written_is_refused_before_any_work(tmp_path):
    """identify, compare and simulate refuse an existing output (the log's, or a simulated log's truth file) or a
    missing folder before they import the numerics or read or simulate anything (simulate ran the whole simulation
    first): one process runs every refusal and then finds numba, scipy and pandas never imported."""
    import subprocess
    import sys

    taken = tmp_path / "taken.json"
    taken.write_text("{}")
    (tmp_path / "sim.csv.truth.json").write_text("{}")
    runs = [
        ["identify", str(SAMPLE_CSV), "-o", str(taken)],
        ["compare", str(SAMPLE_CSV), "-o", str(taken)],
        ["simulate", "-o", str(taken)],
        ["simulate", "-o", str(tmp_path / "sim.csv")],
        ["simulate", "-o", str(tmp_path / "no" / "sim.csv")],
    ]
    code = (
        "import json, sys\n"
        "from wmrid.cli import main\n"
        "out = []\n"
        "for args in json.loads(sys.argv[1]):\n"
        "    try:\n"
        "        main(args)\n"
        "    except SystemExit as stop:\n"
        "        out.append(stop.code)\n"
        "print(json.dumps([out, sorted(m for m in ('numba', 'scipy', 'pandas') if m in sys.modules)]))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code, json.dumps(runs)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    codes, imported = json.loads(proc.stdout)
    assert codes == [2] * len(runs), proc.stderr
    assert imported == [], imported
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == len(runs), proc.stderr
    assert [line.startswith("wmrid: error: ") for line in lines] == [True] * len(runs), proc.stderr
    assert "sim.csv.truth.json exists; use --force" in lines[3]
    assert "folder" in lines[4]
    assert not (tmp_path / "sim.csv").exists()


def test_paper_settings_are_reproducible_by_flags_and_warn_when_they_do_not_converge():
    out = identify_json(str(SAMPLE_CSV), "--robot", "paper", "--k", "1", "--alpha", "5000")
    assert out["settings"]["alpha"] == 5000
    assert out["settings"]["k"] == 1
    assert any("start value, not the data, sets them" in w for w in out["warnings"])


def test_missing_column_is_a_one_line_error(tmp_path):
    bad = tmp_path / "renamed.csv"
    lines = SAMPLE_CSV.read_text().splitlines()[:200]
    # "tau_2" does not say which wheel (so it is not guessed, as "tau_left" would be:
    # tests/unit/io/test_column_guess.py)
    bad.write_text("\n".join([lines[0].replace("tau_l", "tau_2"), *lines[1:]]) + "\n")
    line = assert_clean_error(wmrid("identify", str(bad)), 2, "renamed.csv", "tau_l", "--columns tau_l=tau_2")
    assert "did you mean" in line


def test_column_mapping_option_reads_other_names(tmp_path):
    renamed = tmp_path / "renamed.csv"
    text = SAMPLE_CSV.read_text().splitlines()
    renamed.write_text("\n".join(["time,wr,wl,er,el", *text[1:]]) + "\n")
    mapped = identify_json(str(renamed), "--robot", "paper", "--columns", "t=time,eta_r=wr,eta_l=wl,tau_r=er,tau_l=el")
    direct = identify_json(str(SAMPLE_CSV), "--robot", "paper")
    assert mapped["parameters"] == direct["parameters"]


@pytest.mark.parametrize(
    ("content", "needles"),
    [
        (b"", ["empty.csv", "empty"]),
        (b"t,eta_r,eta_l,tau_r,tau_l\n", ["empty.csv", "no data"]),
    ],
)
def test_empty_file_is_a_one_line_error(tmp_path, content, needles):
    path = tmp_path / "empty.csv"
    path.write_bytes(content)
    assert_clean_error(wmrid("identify", str(path)), 2, *needles)
    assert path.read_bytes() == content


def test_missing_file_and_unknown_robot(tmp_path):
    assert_clean_error(wmrid("identify", str(tmp_path / "nope.csv")), 2, "nope.csv")
    assert_clean_error(wmrid("identify", str(SAMPLE_CSV), "--robot", "nope"), 2, "nope", "paper")


def test_debug_shows_the_traceback(tmp_path):
    """A real process: --debug lets the exception reach the interpreter, which prints its traceback."""
    proc = process("--debug", "identify", str(tmp_path / "nope.csv"))
    assert proc.returncode != 0
    assert "Traceback" in proc.stderr.decode()


def test_help_and_version():
    proc = wmrid("--help")
    assert proc.returncode == 0
    assert b"identify" in proc.stdout
    assert b"simulate" in proc.stdout
    assert wmrid("--version").stdout.startswith(b"wmrid ")


def test_every_commands_help_fits_an_80_column_terminal():
    """Issue 33: ``wmrid COMMAND --help`` at 80 columns fits in 120 lines (identify's was 243), no line wider than the
    terminal; the panels of detail (the log's input, the observer) fold into one line naming ``--help-all``, which
    shows every option.  Measured: identify 101 lines, fleet 116, plan 110, simulate 107 (was 148)."""
    from wmrid.cli.app import command

    for name, cmd in command().commands.items():
        if getattr(cmd, "hidden", False):
            continue
        shown = text(wmrid(name, "--help", columns="80"))
        assert shown.returncode == 0, name
        lines = shown.stdout.splitlines()
        assert len(lines) <= 120, (name, len(lines))
        assert max(len(line) for line in lines) <= 80, name
    short = text(wmrid("identify", "--help", columns="80")).stdout
    every = text(wmrid("identify", "--help-all", columns="80")).stdout
    assert "│ --help-all " in short  # a row of the options, not only the folded panels' line
    assert "--robot" in short
    for flag in ("--topic", "--speed-unit", "--torque-hold", "--box-width"):
        assert flag not in short, flag
        assert flag in every, flag
    assert "Log input (bag topics, units, effort): 19 options" in " ".join(short.split())
    assert len(every.splitlines()) > len(short.splitlines())


def test_the_help_shows_a_value_only_for_options_that_take_one():
    """Typer 0.29 writes a type beside every option: ``<bool>`` beside a flag such as ``--force``, which takes no value,
    and ``<list[str]>`` beside a repeated argument or option.  The help shows none for a flag or a repeated argument
    (the usage line says ``{LOG}...``) and the element's type, repeated, for a repeatable option; ``wmrid --help``
    lists identify first."""
    from wmrid.cli.app import command

    for name, cmd in command().commands.items():
        if getattr(cmd, "hidden", False):
            continue
        every = text(wmrid(name, "--help-all", columns="200")).stdout
        assert "<bool>" not in every, name
        assert "<list[" not in every, name
    plan = text(wmrid("plan", "--help", columns="200")).stdout
    assert any(line.split()[1:3] == ["--given", "<str>..."] for line in plan.splitlines() if "--given" in line)
    assert "Usage: wmrid identify [OPTIONS] {LOG}..." in text(wmrid("identify", "--help", columns="200")).stdout
    root = text(wmrid("--help", columns="200")).stdout
    commands = [line.split()[1] for line in root.splitlines() if line.startswith("│ ") and line.split()[1].isalpha()]
    assert commands[0] == "identify", commands


def test_an_error_on_a_terminal_is_wrapped_at_word_boundaries(tmp_path):
    """Issue 33: an error line is one line in a pipe (scripts, logs) and, on an 80-column terminal, wrapped at its
    width between words (the terminal broke it mid-word), the lines after the first indented: the same words."""
    import os
    import pty
    import subprocess
    import sys

    args = ["identify", str(ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"), "--k=-1"]  # a path within 80 columns
    piped = text(process(*args))
    assert piped.returncode == 2
    assert len(piped.stderr.splitlines()) == 1
    assert len(piped.stderr) > 100
    leader, follower = pty.openpty()
    env = dict(os.environ, COLUMNS="80")
    proc = subprocess.run(
        [sys.executable, "-m", "wmrid", *args], stderr=follower, stdout=subprocess.PIPE, env=env, timeout=300
    )  # fmt: skip
    os.close(follower)
    shown = b""
    while True:
        try:
            chunk = os.read(leader, 65536)
        except OSError:  # the terminal's other end closed
            break
        if not chunk:
            break
        shown += chunk
    os.close(leader)
    lines = shown.decode().replace("\r\n", "\n").rstrip("\n").split("\n")
    assert proc.returncode == 2
    assert len(lines) > 1
    assert all(len(line) <= 80 for line in lines), lines
    assert all(line.startswith("  ") for line in lines[1:])
    assert " ".join(line.strip() for line in lines) == piped.stderr.strip()


def test_the_command_is_built_once_and_answers_alike_every_time():
    """``command()`` (Typer's build of the app, 50 ms) is made once per process: the same object each call, its help
    texts escaped once (the brackets still shown as written after reuse), and a run after a refused one answers as
    the first did."""
    from wmrid.cli.app import command

    assert command() is command()
    first = text(wmrid("identify", "--help", columns="80"))
    refused = text(wmrid("identify", "/nonexistent/wmrid-test/log.csv", "--k=-1"))
    assert refused.returncode == 2
    assert "--k" in refused.stderr
    again = text(wmrid("identify", "--help", columns="80"))
    assert first.returncode == again.returncode == 0
    assert "[m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2]" in first.stdout
    assert again.stdout == first.stdout
    assert text(wmrid("identify", "/nonexistent/wmrid-test/log.csv", "--k=-1")).stderr == refused.stderr


def test_simulate_writes_log_and_truth_then_identify_recovers_it(tmp_path):
    log = tmp_path / "sim.parquet"
    proc = wmrid("simulate", "-o", str(log), "--duration", "20", "--seed", "3")
    assert proc.returncode == 0, proc.stderr.decode()
    truth = truth_of(log)
    expected = model.named_base(model.base_parameters(BUILTIN_ROBOTS["paper"].cad))
    assert truth == pytest.approx(expected, rel=1e-15)
    out = identify_json(str(log), "--robot", "paper")
    for name in REPORTED:
        assert out["parameters"][name]["value"] == pytest.approx(truth[name], rel=5e-3), name
    assert_clean_error(wmrid("simulate", "-o", str(log), "--duration", "1"), 2, "--force")


def test_simulate_with_payload_changes_the_truth(tmp_path):
    log = tmp_path / "loaded.csv"
    proc = wmrid(
        "simulate", "-o", str(log), "--duration", "20", "--payload", "25@0.1,-0.05", "--payload-inertia", "0.4"
    )
    assert proc.returncode == 0, proc.stderr.decode()
    sidecar = json.loads(Path(str(log) + ".truth.json").read_text())
    loaded = BUILTIN_ROBOTS["paper"].cad.with_payload(Payload(25.0, 0.1, -0.05, 0.4))
    assert sidecar["parameters"] == pytest.approx(model.named_base(model.base_parameters(loaded)), rel=1e-15)
    assert sidecar["payload"] == {"mass": 25.0, "x": 0.1, "y": -0.05, "inertia": 0.4}
    out = identify_json(str(log), "--robot", "paper")
    for name in ("m11", "m12", "m22", "Vc"):
        assert out["parameters"][name]["value"] == pytest.approx(sidecar["parameters"][name], rel=5e-3), name


def test_simulate_reversing_selects_the_general_form(tmp_path):
    log = tmp_path / "rev.csv"
    assert wmrid("simulate", "-o", str(log), "--duration", "20", "--trajectory", "reversing").returncode == 0
    out = identify_json(str(log), "--robot", "paper")
    assert out["theta"]["form"]["kind"] == "general"
    with pytest.raises(AssertionError):
        identify_json(str(log), "--form", "paper")
    assert_clean_error(wmrid("identify", str(log), "--form", "paper"), 2, "--form general")


def test_identify_out_writes_the_estimates_as_mcap(tmp_path):
    from wmrid.io.mcap.reader import read_mcap

    target = tmp_path / "estimates.mcap"
    out = identify_json(str(SAMPLE_PARQUET), "--robot", "paper", "--mcap-out", str(target))
    fields = {"theta11": "theta11", "e_r": "e_r", "t": "t", "m11": "m11", "m11_std": "m11_std", "Fd2": "Fd2"}
    contents = read_mcap(str(target), json_fields={"/wmrid/estimates": fields})
    series = contents.json["/wmrid/estimates"]
    assert len(series.log_ns) > 1000
    assert series.values["theta11"][-1] == pytest.approx(out["theta"]["values"]["theta11"], rel=1e-12)
    # the base parameters over time (closed-form recovery: theta11 is m11) and the final std in every message
    assert np.array_equal(series.values["m11"], series.values["theta11"])
    assert np.all(series.values["m11_std"] == out["parameters"]["m11"]["std"])
    assert series.values["Fd2"][-1] == pytest.approx(out["parameters"]["Fd2"]["value"], rel=1e-3)
    assert np.all(np.diff(series.values["t"]) > 0)
    assert json.loads(contents.metadata["wmrid"]["result"])["parameters"] == out["parameters"]
    refused = wmrid("identify", str(SAMPLE_PARQUET), "--mcap-out", str(tmp_path / "x.json"))
    assert_clean_error(refused, 2, "--mcap-out", ".mcap")


def test_identify_reads_an_mcap_from_a_pipe():
    bag = ROOT / "sample_logs" / "paper_sinusoid.mcap"
    from_pipe = identify_json("-", "--robot", "paper", stdin=bag.read_bytes())
    from_file = identify_json(str(bag), "--robot", "paper")
    assert from_pipe["parameters"] == from_file["parameters"]


def test_inspect_csv_and_parquet(tmp_path):
    for path in (SAMPLE_CSV, SAMPLE_PARQUET):
        proc = wmrid("inspect", str(path), "--format", "json")
        assert proc.returncode == 0, proc.stderr.decode()
        assert proc.stderr == b""
        info = json.loads(proc.stdout)
        assert [c["name"] for c in info["columns"]][:5] == ["t", "eta_r", "eta_l", "tau_r", "tau_l"]
        assert info["canonical_missing"] == []
    commented = tmp_path / "robot.txt"
    commented.write_text("% 1 time\n% 2 3 wheel velocity left right\n0.0 1 2\n0.1 1 2\n")
    info = json.loads(wmrid("inspect", str(commented), "--format", "json").stdout)
    assert [c["name"] for c in info["columns"]] == ["1", "2", "3"]
    assert info["comments"] == ["% 1 time", "% 2 3 wheel velocity left right"]


def test_fleet_records_no_options_when_none_are_given():
    """wmrid fleet's "options" column holds only the flags given a value other than identify's default, and the
    library's fleet() records {} for a call without options: the command's own defaults give {} too, so a table the
    command wrote is resumed by the library (and back) without identifying its logs again.  (The command's table
    said {"method": "auto"} while identify's default had become "auto": resume then matched nothing.)"""
    import inspect

    from wmrid.cli.fleet_commands import _given_options, fleet_command
    from wmrid.cli.groups import FIT_FLAGS, LOG_FLAGS, OBSERVER_FLAGS

    defaults = {
        name: param.default.default if hasattr(param.default, "default") else param.default
        for name, param in inspect.signature(fleet_command).parameters.items()
    }
    made = [group.make(defaults) for group in (LOG_FLAGS, OBSERVER_FLAGS, FIT_FLAGS)]
    assert _given_options(*made, defaults["method"].value, defaults["rotor_inertia"]) == {}


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["identify", "--nope"], ["No such option: --nope", "see wmrid identify --help"]),
        (["identify", "run.csv", "--k", "abc"], ["Invalid value for '--k'", "see wmrid identify --help"]),
        (["identify"], ["Missing argument 'LOG'; see wmrid identify --help"]),
        (["idnetify", "x"], ["No such command 'idnetify'. Did you mean 'identify'?", "see wmrid --help"]),
    ],
)
def test_a_command_line_mistake_is_one_line_naming_where_to_look(args, needles):
    """A flag, value or argument click refuses: one line, exit 2, naming the command's --help (click printed a
    four-line usage block)."""
    assert_clean_error(wmrid(*args), 2, *needles)


def test_wmrid_alone_shows_its_help_and_no_error_line():
    """``wmrid`` without a command: the help on stdout, exit 2 as click's, and no "error" on stderr (the one-line
    usage errors had turned it into "wmrid: error: ; see wmrid --help")."""
    proc = wmrid()
    assert proc.returncode == 2
    assert b"Usage" in proc.stdout
    assert b"error" not in proc.stderr
