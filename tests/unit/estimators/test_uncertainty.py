"""Standard errors: the segment jackknife against brute force, t quantiles against tables."""

from __future__ import annotations

import numpy as np
import pytest

from wmrid.estimators.uncertainty import interval_factor, jackknife_covariance, segment_count


def blocked_regression(seed: int, n_blocks: int = 60, per_block: int = 25, p: int = 4, rho: float = 0.0):
    """Synthetic data u = w theta + r in blocks, with AR(1) residuals; returns the per-block sums too."""
    rng = np.random.default_rng(seed)
    n = n_blocks * per_block
    w = rng.standard_normal((n, p)) + np.linspace(0, 1, n)[:, None] * rng.standard_normal(p)
    theta = rng.standard_normal((2, p))
    r = np.zeros((n, 2))
    e = rng.standard_normal((n, 2))
    for i in range(1, n):
        r[i] = rho * r[i - 1] + e[i]
    u = w @ theta.T + r
    h = 1e-3
    blk = np.repeat(np.arange(n_blocks), per_block)
    blk_a = np.stack([h * w[blk == j].T @ w[blk == j] for j in range(n_blocks)])
    blk_c = np.stack([h * (u[blk == j].T @ w[blk == j]) for j in range(n_blocks)])  # (J, 2, p)
    return w, u, blk, blk_a, blk_c, h, theta


def test_jackknife_equals_refitting_without_each_segment():
    w, u, blk, blk_a, blk_c, h, _ = blocked_regression(3)
    alpha = 1e-6
    p = w.shape[1]
    gamma = alpha * np.eye(p) + blk_a.sum(axis=0)
    theta = np.linalg.solve(gamma, blk_c.sum(axis=0).T).T  # prior mean 0
    n_seg = 6
    segment = np.repeat(np.arange(n_seg), len(blk_a) // n_seg)
    got = jackknife_covariance(gamma, theta, blk_a, blk_c, segment, n_seg)
    # Brute force: ridge-least-squares on the raw samples with each segment's samples removed.
    fits = []
    for g in range(n_seg):
        keep = ~np.isin(blk, np.flatnonzero(segment == g))
        a = np.vstack([np.sqrt(h) * w[keep], np.sqrt(alpha) * np.eye(p)])
        b = np.vstack([np.sqrt(h) * u[keep], np.zeros((p, 2))])
        fits.append(np.linalg.lstsq(a, b, rcond=None)[0].T.ravel())
    fits = np.array(fits)
    centred = fits - fits.mean(axis=0)
    expected = (n_seg - 1) / n_seg * centred.T @ centred
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


@pytest.mark.slow  # Monte Carlo over 200 seeds
def test_jackknife_standard_errors_match_the_spread_over_seeds():
    # Seeded Monte Carlo with AR(1) residuals (rho 0.7: integrated memory 5.7 samples, segments of 50): the reported
    # std must match the actual spread.  200 replications give the ratio to about +/- 10 % (2 sigma), and
    # memory / segment length leaves a downward bias of about 10 %.
    ests, stds = [], []
    for seed in range(200):
        _w, _u, _blk, blk_a, blk_c, _h, truth = blocked_regression(seed, n_blocks=200, per_block=5, p=3, rho=0.7)
        gamma = 1e-9 * np.eye(3) + blk_a.sum(axis=0)
        theta = np.linalg.solve(gamma, blk_c.sum(axis=0).T).T
        segment = np.repeat(np.arange(20), 10)
        cov = jackknife_covariance(gamma, theta, blk_a, blk_c, segment, 20)
        ests.append((theta - truth).ravel())
        stds.append(np.sqrt(np.diag(cov)))
    ratio = np.sqrt(np.mean(np.square(ests), axis=0)) / np.sqrt(np.mean(np.square(stds), axis=0))
    assert np.all(np.abs(ratio - 1) < 0.2), ratio


@pytest.mark.parametrize(("coverage", "dof", "table"), [(0.95, 9, 2.262157), (0.95, 19, 2.093024), (0.9973, 1e9, 3.0)])
def test_interval_factor_is_students_t(coverage, dof, table):
    assert interval_factor(coverage, dof) == pytest.approx(table, abs=2e-3 if dof > 1e6 else 1e-6)


def test_segment_count_bounds():
    assert segment_count(40.0, 4000) == 20
    assert segment_count(3.0, 4000) == 10
    assert segment_count(3600.0, 65536) == 40
    assert segment_count(3.0, 4) == 4


def test_slow_residual_is_the_ratio_of_mean_square_errors_with_its_jackknife():
    """slow_residual on block sums made by hand: 40 blocks of 0.1 s over 4 segments, the slow ones (every 4th)
    with 2.25 times the error power of the others on wheel 0 and the same on wheel 1: ratio exactly (2.25, 1.0), the
    jackknife std of the log-ratio zero for exactly proportional blocks (z infinite is reported as 0) and the slow
    parts departing on wheel 0 only when the segments scatter; a second case with a ratio of 1.2 does not depart."""
    from types import SimpleNamespace

    from wmrid.estimators.model_error import slow_residual

    rng = np.random.default_rng(4)
    n = 40
    ends = 0.1 * np.arange(1, n + 1)
    slow = np.arange(n) % 4 == 0
    segment = np.arange(n) // 10
    for factor, departs in ((2.25, True), (1.2, False)):
        power = np.where(slow[:, None], [factor, 1.0], [1.0, 1.0]) * rng.uniform(0.9, 1.1, size=(n, 1))
        out = SimpleNamespace(blk_ee=0.1 * power, block_t=ends)
        got = slow_residual(out, slow, segment, 4, 4.0)
        exact = (power[slow].mean(axis=0) / power[~slow].mean(axis=0)).tolist()
        assert got["ratio"] == pytest.approx(exact, rel=1e-12)
        assert got["departs"] is departs
        assert got["z"][0] > 1.0  # proportional noise on both groups: the slow excess is many jackknife std


def test_slow_parts_fit_like_the_rest_where_the_model_holds():
    """wmrid's simulator (the model holds), the light AMR reversing 30 s with speed noise 0.02 rad/s: the slow parts'
    prediction error is the noise, as elsewhere (measured 1.04 and 1.04; asserted within 0.8-1.25, well under the
    gate of 1.5).  (The difference of the estimates passes its gate of 3 std on this seed, 3.57: the about 5 % of
    well-specified logs that gate lets through by chance; the residual test does not add to them.)"""
    import wmrid

    sim = wmrid.simulate(
        "amr", trajectory="reversing", duration=30.0, noise=wmrid.NoiseSettings(seed=3, eta_std=0.02, tau_std=0.01)
    )
    slow = wmrid.identify(sim.log.to_wheel_log(), "amr").diagnostics.model_error.slow_speed
    assert all(0.8 < r < 1.25 for r in slow.residual_ratio), slow.residual_ratio
