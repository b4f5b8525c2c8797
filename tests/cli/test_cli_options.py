"""Options declared once (wmrid/cli/options.py and the groups of wmrid/cli/groups.py; issue 31): every command that
identifies a log offers the log and observer flags ``wmrid identify`` offers, spelled, explained and defaulted the
same, unless this file says why not."""

from __future__ import annotations

from locations import ROOT_DIR

from wmrid.cli.app import command

#: identify's own outputs: what it writes, not how it reads or identifies a log.
OUTPUTS = {"output", "output_format", "force", "mcap_out", "out", "history", "no_history", "verbose"}
#: The flags of identify a command leaves out, and why.
NOT_OFFERED = {
    "compare": {
        "method": "compare runs every method of --methods",
        "given": "each method's estimate is shown as this log gives it",
    },
    "report": {"log": "report's INPUT is a log or a saved result"},
    "fleet": {
        "log": "fleet's LOGS are many",
        "validate": "each log of a fleet is its own; fleet-report compares them",
        "given": "each log of a fleet is identified on its own",
    },
    "live": {
        "log": "live's SOURCE is a stream",
        "method": "live runs the observer, the online estimator",
        "cutoff": "a classical method's setting (live runs the observer)",
        "weighted": "a classical method's setting (live runs the observer)",
        "forgetting": "a classical method's setting (live runs the observer)",
        "validate": "live follows one source",
        "given": "live reports the source as it comes",
    },
    "monitor": {
        **{name: "monitor tests the log against its --model; the identifications after a change are the observer's"
           for name in ("robot", "method", "cutoff", "weighted", "forgetting", "given", "rotor_inertia")},
        "payload": "the identifications after a change have no robot file to weigh a payload against",
        "validate": "monitor reports each segment's parameters, not a fit on another log",
    },
}  # fmt: skip
#: Flags a command offers with its own help, and why.
OWN_HELP = {
    "monitor": {
        "delay": "monitor shifts the whole log before the test and runs no timing check",
        "friction": "monitor identifies with its --model's friction model",
    },
}
#: Flags whose help names the command's own role (the robot's, the first argument's).
OWN_WORDS = {"robot", "log"}


def test_every_command_that_identifies_offers_identifys_flags() -> None:
    root = command()
    identify = {p.name: p for p in root.commands["identify"].params}
    for name, exempt in NOT_OFFERED.items():
        params = {p.name: p for p in root.commands[name].params}
        missing = set(identify) - set(params) - set(exempt) - OUTPUTS
        assert not missing, (name, sorted(missing))
        for flag in (set(identify) & set(params)) - OUTPUTS - OWN_WORDS:
            ours, theirs = params[flag], identify[flag]
            assert ours.opts == theirs.opts, (name, flag)
            if flag not in OWN_HELP.get(name, {}):
                assert getattr(ours, "help", None) == getattr(theirs, "help", None), (name, flag)
            assert ours.default == theirs.default, (name, flag)


def test_compare_passes_the_observers_settings(tmp_path) -> None:
    """``compare --k 2`` runs the observer with k = 2, as ``identify --k 2 --method observer`` does."""
    import json

    from cliutil import wmrid

    sample = ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"
    args = (str(sample), "--robot", "paper", "--k", "2", "--format", "json")
    compared = json.loads(wmrid("compare", *args, "--methods", "observer").stdout)
    identified = json.loads(wmrid("identify", *args, "--method", "observer").stdout)
    for name, entry in compared["methods"]["observer"]["parameters"].items():
        assert entry["value"] == identified["parameters"][name]["value"], name
    assert identified["settings"]["k"] == 2.0


def test_every_choice_the_command_line_offers_is_the_librarys() -> None:
    """Each option with a fixed set of values offers one of wmrid.core.choices' enums (or the output format, the
    command line's own) as it is: no command keeps a list of its own that the library's checks could drift from."""
    import enum

    from wmrid.cli.options import OutputFormat
    from wmrid.core import choices

    library = {
        item
        for item in vars(choices).values()
        if isinstance(item, type) and issubclass(item, enum.Enum) and item.__module__ == choices.__name__
    }
    seen = 0
    for name, sub in command().commands.items():
        for param in sub.params:
            described = getattr(param, "type_descriptor", None)
            if described is not None and described.is_choice:
                seen += 1
                assert described.annotation in library | {OutputFormat}, (name, param.name, described.annotation)
    assert seen > 30
