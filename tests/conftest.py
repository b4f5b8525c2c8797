"""Shared fixtures: small logs with a known truth, made here (no files needed)."""

from __future__ import annotations

import pytest

from tests.open_loop import open_loop_log


@pytest.fixture(scope="session")
def smooth_log():
    return open_loop_log()


@pytest.fixture(scope="session")
def long_smooth_log():
    return open_loop_log(duration=40.0)


@pytest.fixture(scope="session")
def amr_caster_log():
    """The light AMR on the MuJoCo multibody prototype: ball casters of rolling resistance 0.015, reversing at
    200 Hz, sensor noise 0.02 rad/s and 0.002 N m, seed 0 (issue 11's AMR configuration; about 3 s to simulate,
    so shared by every test that needs it)."""
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.multibody import MultibodySettings, simulate_multibody
    from wmrid.sim.scenario import NoiseSettings

    amr = BUILTIN_ROBOTS["amr"]
    return simulate_multibody(
        amr.cad, amr.nominal, casters=amr.casters, settings=MultibodySettings(caster_resistance=0.015),
        trajectory="reversing", rate=200, noise=NoiseSettings(eta_std=0.02, tau_std=0.002), seed=0,
    )  # fmt: skip
