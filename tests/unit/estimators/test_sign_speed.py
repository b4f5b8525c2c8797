"""wmrid.estimators.sign_speed: the centred mean the sign columns take their sign from, whole and streamed."""

from __future__ import annotations

import numpy as np
import pytest

from wmrid.estimators.sign_speed import SignSpeeds, centred_mean, sign_half_window


@pytest.mark.parametrize(("n", "h"), [(1, 3), (5, 3), (100, 10), (1000, 10), (37, 0)])
def test_streamed_equals_whole_bit_for_bit(n, h):
    """The mean of each window (cut short at the ends) against a direct per-sample mean (1e-13), and the streamed
    version, fed in random pieces, equal to the whole-log one bit for bit with every sample given out once, in order
    (a run of exact zeros included: its mean is exactly 0 either way)."""
    rng = np.random.default_rng(n + h)
    eta = rng.normal(size=(n, 2))
    eta[10:20] = 0.0
    t = np.arange(n) * 1e-3
    tau = rng.normal(size=(n, 2))
    whole = centred_mean(eta, h)
    direct = np.array([eta[max(0, i - h) : min(n, i + h + 1)].mean(axis=0) for i in range(n)])
    np.testing.assert_allclose(whole, direct, rtol=1e-13, atol=1e-15)
    for _ in range(20):
        cuts = np.sort(rng.integers(0, n + 1, size=rng.integers(0, 6)))
        signs = SignSpeeds(h)
        outs = [signs.feed(t[a:b], eta[a:b], tau[a:b]) for a, b in zip(np.r_[0, cuts], np.r_[cuts, n], strict=True)]
        outs.append(signs.finish())
        for j, ref in enumerate((t, eta, tau, whole)):
            assert np.array_equal(np.concatenate([o[j] for o in outs]), ref)


def test_half_window_follows_the_rate():
    """20 ms in all: 10 samples each side at 1 kHz, 1 at 100 Hz, none at 50 Hz; none for a log of one sample."""
    assert sign_half_window(60_001, 60.0) == 10
    assert sign_half_window(6_001, 60.0) == 1
    assert sign_half_window(3_001, 60.0) == 0
    assert sign_half_window(1, 0.0) == 0


def test_the_compiled_window_means_equal_numpys_offset_sums_bit_for_bit() -> None:
    """The kernel sums each window as numpy's loop over the offsets did (0.0 + x[i - h] + ... + x[i + h], cut at the
    ends), so its means are the same bits, whatever context the window has on either side."""
    import numpy as np

    from wmrid.estimators.sign_speed import _window_means

    def offsets(x, h, left, right):
        n = x.shape[0]
        idx = np.arange(left, n - right)
        total = np.zeros((len(idx), 2))
        for k in range(-h, h + 1):
            rows = idx + k
            inside = (rows >= 0) & (rows < n)
            total[inside] += x[rows[inside]]
        return total / (np.minimum(idx + h + 1, n) - np.maximum(idx - h, 0))[:, None]

    x = np.random.default_rng(5).standard_normal((2000, 2)) * 10.0 ** np.arange(-3, 3)[np.arange(2000) % 6, None]
    for h, left, right in [(10, 0, 0), (10, 7, 10), (3, 3, 0), (500, 20, 5), (1, 0, 1), (0, 0, 0)]:
        assert np.array_equal(_window_means(x, h, left, right), offsets(x, h, left, right)), (h, left, right)
