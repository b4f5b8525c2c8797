"""Fuzzing the reader and the identify path: mutated CSV, Parquet and MCAP bytes give a result or a
WmridError (a clear message), never another exception, within a time bound."""

from __future__ import annotations

import io
import time
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from wmrid.core.errors import WmridError
from wmrid.io.logs import read_log, write_log
from wmrid.io.mcap.writer import write_joint_state_mcap
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify
from wmrid.sim.simulate import simulate

#: Wall-clock bound per example, s (a 200-sample log reads and identifies in about 0.05 s).
TIME_BOUND_S = 10.0


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> dict[str, bytes]:
    robot = BUILTIN_ROBOTS["paper"]
    sim = simulate(robot.reference, robot.nominal, duration=0.3, seed=0)
    frame = sim.to_frame()
    folder = tmp_path_factory.mktemp("fuzz-seeds")
    out = {}
    for suffix in (".csv", ".parquet"):
        path = folder / f"seed{suffix}"
        write_log(frame[["t", "eta_r", "eta_l", "tau_r", "tau_l"]], str(path))
        out[suffix] = path.read_bytes()
    path = folder / "seed.mcap"
    write_joint_state_mcap(path, frame, odom_topic=None, chunk_size=4096)
    out[".mcap"] = path.read_bytes()
    return out


@st.composite
def mutations(draw, size: int):
    """A list of (kind, position, payload) edits: flip a byte, insert bytes, delete a run, or truncate."""
    edits = []
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["flip", "insert", "delete", "truncate"]))
        pos = draw(st.integers(0, max(size - 1, 0)))
        payload = draw(st.binary(min_size=1, max_size=8))
        edits.append((kind, pos, payload))
    return edits


def mutate(data: bytes, edits) -> bytes:
    buf = bytearray(data)
    for kind, pos, payload in edits:
        pos = min(pos, max(len(buf) - 1, 0))
        if not buf:
            break
        if kind == "flip":
            buf[pos] ^= payload[0] or 0xFF
        elif kind == "insert":
            buf[pos:pos] = payload
        elif kind == "delete":
            del buf[pos : pos + len(payload)]
        else:
            del buf[pos:]
    return bytes(buf)


def run_path(tmp_path, suffix: str, data: bytes) -> None:
    path = tmp_path / f"fuzzed{suffix}"
    path.write_bytes(data)
    start = time.perf_counter()
    message = None
    try:
        log = read_log(str(path))
        identify(SimpleNamespace(t=log.t, eta=log.eta, tau=log.tau, source=log.source, notes=log.notes), None)
    except WmridError as err:  # the only acceptable failure: anything else propagates and fails the test
        message = str(err).strip()
    if message is not None:
        assert message, "an error needs a message"
        assert "\n" not in message
    assert time.perf_counter() - start < TIME_BOUND_S


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".mcap"])
@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_logs_give_a_result_or_a_clear_error(tmp_path, seeds, suffix, data):
    original = seeds[suffix]
    edits = data.draw(mutations(len(original)))
    run_path(tmp_path, suffix, mutate(original, edits))


def test_mutate_is_deterministic_and_changes_bytes():
    assert mutate(b"abcdef", [("flip", 0, b"\x01")]) == b"`bcdef"
    assert mutate(b"abcdef", [("truncate", 3, b"x")]) == b"abc"
    assert mutate(b"abcdef", [("insert", 2, b"XY")]) == b"abXYcdef"
    assert mutate(b"abcdef", [("delete", 1, b"xx")]) == b"adef"
    assert np.frombuffer(io.BytesIO(b"\x00").getvalue(), dtype=np.uint8)[0] == 0
