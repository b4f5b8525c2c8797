"""``wmrid live --monitor MODEL.json`` (issue 32): the change test of ``wmrid monitor`` along a stream.

The logs are those of tests/unit/monitoring/test_monitor.py: the paper robot (CAD set, controller on the nominal set) on
the sinusoid at 1 kHz with 0.01 rad/s speed noise, 0.02 N m torque noise and a 0.05 N m caster disturbance (0.3 s
correlation), every simulation seeded; the model is identified on ANOTHER log of the robot (seed 101), as a user would.
Streams are sent faster than real time; nothing is timed.
"""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest
from locations import ROOT_DIR

import wmrid
from tests.fxserver import Publisher, read_recording
from wmrid.model.robot import BUILTIN_ROBOTS, Payload
from wmrid.sim.scenario import NoiseSettings, PlantChange
from wmrid.sim.simulate import simulate

TRUE = BUILTIN_ROBOTS["paper"].cad
NOMINAL = BUILTIN_ROBOTS["paper"].nominal
LOAD = Payload(25.0, 0.1, -0.05, 0.4)
NOISE = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)


def frame_of(sim):
    import pandas as pd

    return pd.DataFrame({"t": sim.t, "eta_r": sim.eta[:, 0], "eta_l": sim.eta[:, 1], "tau_r": sim.tau[:, 0],
                         "tau_l": sim.tau[:, 1]})  # fmt: skip


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """(the model's JSON file, the loaded run as an MCAP of JointState messages, the time the payload was loaded)."""
    from wmrid.io.mcap.writer import write_joint_state_mcap

    folder = tmp_path_factory.mktemp("livemon")
    unloaded = simulate(TRUE, NOMINAL, duration=60.0, noise=NOISE, seed=101)
    model = folder / "model.json"
    log = wmrid.WheelLog(t=unloaded.t, eta=unloaded.eta, tau=unloaded.tau, source="id.csv")
    model.write_text(json.dumps(wmrid.identify(log, "paper").to_dict()))
    load = PlantChange.payload_load(20.0, TRUE, LOAD)
    loaded = simulate(TRUE, NOMINAL, duration=40.0, noise=NOISE, seed=1, change=load)
    run = folder / "loaded.mcap"
    write_joint_state_mcap(run, frame_of(loaded), odom_topic=None)
    return model, run, loaded.settings["change"]["t_switch"]


def test_payload_loaded_at_20_s_streamed_over_websocket(files):
    """The loaded run streamed by the foxglove-sdk server (as fast as it can), `wmrid live --monitor` on the command
    line: one JSON line with "event": "change" within 3 s of log time of the load, naming the payload's terms and its
    mass; the alarm is the offline monitor's on the same messages."""
    from tests.cliutil import wmrid as run

    model, path, t_switch = files
    pub = Publisher(read_recording(str(path)))
    sender = threading.Thread(target=pub.publish, kwargs={"speed": 0.0}, daemon=True)
    sender.start()
    try:
        proc = run("live", f"ws://127.0.0.1:{pub.port}", "--robot", "paper", "--monitor", str(model), "--idle", "1",
                   "--format", "json")  # fmt: skip
    finally:
        pub.stop()
    sender.join(120)
    assert proc.returncode == 0, proc.stderr.decode()
    lines = [json.loads(line) for line in proc.stdout.decode().splitlines()]
    changes = [line for line in lines if line["event"] == "change"]
    assert len(changes) == 1, changes
    change = changes[0]
    assert t_switch <= change["t_alarm"] <= change["t_raised"] <= t_switch + 3.0
    assert change["t"] == pytest.approx(t_switch, abs=0.2)
    assert change["kind"] == "payload"
    assert {"M11", "M22"} <= set(change["moved"])
    assert change["payload"]["mass"] == pytest.approx(LOAD.mass, rel=0.25)
    offline = wmrid.monitor(str(path), str(model))
    assert len(offline.changes) >= 1
    first = offline.changes[0]
    assert change["t"] == pytest.approx(first.t, abs=1e-9)
    assert change["t_alarm"] == pytest.approx(first.t_alarm, abs=1e-9)
    assert change["statistic"] == pytest.approx(first.statistic, rel=1e-8)
    assert change["threshold"] == pytest.approx(first.threshold, rel=1e-12)
    assert lines[-1]["event"] == "result"


def test_no_alarm_over_5_minutes_of_an_unchanged_stream(files, tmp_path):
    """300 s of the unchanged robot followed from a CSV (read faster than real time): no change, and the monitor
    recalibrated at 20, 40, 80, 160 and 320 s as offline."""
    from wmrid.io.logs import write_log

    model, _, _ = files
    sim = simulate(TRUE, NOMINAL, duration=300.0, noise=NOISE, seed=12)
    path = tmp_path / "long.csv"
    write_log(frame_of(sim), str(path))
    run = wmrid.live(str(path), "paper", monitor=str(model), idle=0.5, every=1.0)
    items = list(run)
    assert [i for i in items if isinstance(i, wmrid.LiveChange)] == []
    final = items[-1]
    assert isinstance(final, wmrid.LiveResult)
    assert final.samples == len(sim.t)
    assert run.monitor.segment.calibrations == 5  # 10, 20, 40, 80, 160 s: the next at 320 s is past the end
    assert not any("monitoring stopped" in e for u in items[:-1] if isinstance(u, wmrid.LiveUpdate) for e in u.events)


def test_live_monitor_fed_in_pieces_is_the_offline_test():
    """In pieces of random sizes, the live monitor's first alarm is the offline monitor's (time, statistic,
    threshold), here for a friction fault (the right wheel's friction tripled at 20 s), told apart as "friction"."""
    from types import SimpleNamespace

    from wmrid.monitoring.live_monitor import LiveMonitor
    from wmrid.monitoring.monitor import monitor
    from wmrid.monitoring.settings import model_from_dict

    unloaded = simulate(TRUE, NOMINAL, duration=60.0, noise=NOISE, seed=101)
    log0 = SimpleNamespace(t=unloaded.t, eta=unloaded.eta, tau=unloaded.tau, source="id.csv", notes=())
    model = model_from_dict(json.loads(json.dumps(wmrid.identify(log0, "paper").to_dict())), "model.json")
    from wmrid.sim.scenario import parse_friction_fault

    fault = PlantChange.friction_fault(20.0, TRUE, *parse_friction_fault("right:3"))
    sim = simulate(TRUE, NOMINAL, duration=30.0, noise=NOISE, seed=3, change=fault)
    offline = monitor(SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source="sim", notes=()), model)
    live = LiveMonitor(model, geometry=(NOMINAL.r, NOMINAL.b))
    rng = np.random.default_rng(5)
    cuts = np.sort(rng.choice(np.arange(1, len(sim.t)), size=300, replace=False))
    found = []
    for a, b in zip([0, *cuts], [*cuts, len(sim.t)], strict=True):
        found += live.feed(sim.t[a:b], sim.eta[a:b], sim.tau[a:b])
    found += live.finish()
    assert len(offline.changes) >= 1
    assert len(found) >= 1
    assert found[0].t_alarm == pytest.approx(offline.changes[0].t_alarm, abs=1e-9)
    assert found[0].statistic == pytest.approx(offline.changes[0].statistic, rel=1e-8)
    assert found[0].kind == "friction"  # the friction terms alone explain it (none alone beyond 3 std: collinear)
    assert set(found[0].moved) <= {"Fv1", "Fv2", "Fd1", "Fd2"}
    assert found[0].payload is None


def test_monitor_model_errors_are_one_line(tmp_path):
    """A --monitor file that is not a result: one line naming it, exit 2, before any connection."""
    from tests.cliutil import wmrid as run

    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    proc = run("live", str(ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"),
               "--monitor", str(bad))  # fmt: skip
    err = proc.stderr.decode()
    assert proc.returncode == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert "bad.json" in err, err
    assert "not a wmrid identify result" in err, err


def test_alarm_line_on_a_terminal(files):
    """--format table (the terminal's view): the change is a highlighted line naming its time, kind and mass."""
    from tests.cliutil import wmrid as run

    model, path, _ = files
    proc = run("live", str(path), "--robot", "paper", "--monitor", str(model), "--format", "table")
    out = proc.stdout.decode()
    assert proc.returncode == 0, proc.stderr.decode()
    assert "CHANGE at 20.01 s (payload; alarm at 20." in out, out
    assert "M11 1.41" in out, out
    assert "payload 2" in " ".join(out.split()), out  # its mass: 2x kg


def test_each_change_line_reads_back_typed_and_writes_the_same_line(files):
    """The change lines `wmrid live --monitor` prints (in process, the loaded run's MCAP): each read as a
    :class:`wmrid.LiveChange` writes back exactly the line it was read from (same keys, same order, same values), its
    payload a :class:`wmrid.PayloadMass`; the terminal's alarm line is made from the typed change."""
    from tests.cliutil import wmrid as run
    from wmrid.reporting.live_view import change_line, json_line

    model, path, _ = files
    proc = run("live", str(path), "--robot", "paper", "--monitor", str(model), "--format", "json")
    assert proc.returncode == 0, proc.stderr.decode()
    lines = [line for line in proc.stdout.decode().splitlines() if json.loads(line)["event"] == "change"]
    assert lines
    for line in lines:
        change = wmrid.LiveChange.from_dict(json.loads(line))
        assert json_line(change.to_dict()) == line
        assert wmrid.LiveChange.from_dict(change.to_dict()) == change
        assert change.delay_s == json.loads(line)["delay_s"]
        assert f"CHANGE at {change.t:.2f} s ({change.kind};" in change_line(change).plain
    payloads = [wmrid.LiveChange.from_dict(json.loads(line)).payload for line in lines]
    assert any(isinstance(p, wmrid.PayloadMass) for p in payloads)
