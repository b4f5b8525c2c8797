"""wmrid.estimators.regression.lowpass against scipy.signal, the implementation it follows (see its module docstring).

Sections and zero-phase filtering are compared for exact equality: the design runs the same floating-point
operations as scipy's butter/zpk2sos and the recursion those of scipy's sosfilt, so any difference is a
departure from scipy, not rounding.  Welch's spectrum removes each segment's line by another least-squares
route than scipy's, so it is compared to 1e-12 of the largest value of each column (observed: 4e-15).
"""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
import scipy.signal as ss
from locations import ROOT_DIR

from wmrid.estimators.regression import lowpass

CUTOFFS = [(2.0, 1000.0), (10.0, 1000.0), (0.05, 1000.0), (0.3, 100.0), (49.0, 100.0), (5.0, 200.0), (123.4, 1000.0)]


@pytest.mark.parametrize("order", range(1, 13))
def test_butter_sos_is_scipys(order):
    rng = np.random.default_rng(order)
    cases = CUTOFFS + [(float(f), 1000.0) for f in rng.uniform(0.01, 499.0, 5)]
    for cutoff, rate in cases:
        ours = lowpass.butter_sos(order, cutoff, rate)
        theirs = ss.butter(order, cutoff, fs=rate, output="sos")
        assert ours.shape == theirs.shape, (order, cutoff, rate)
        assert np.array_equal(ours, theirs), (order, cutoff, rate)


def test_butter_sos_is_a_butterworth():
    """Independently of scipy: |H(f)|^2 = 1 / (1 + (tan(pi f / rate) / tan(pi f_c / rate))^(2 N)), the bilinear
    Butterworth's magnitude, at a few frequencies (to 1e-12)."""
    order, cutoff, rate = 4, 5.0, 1000.0
    sos = lowpass.butter_sos(order, cutoff, rate)
    for f in (0.0, 1.0, 5.0, 20.0, 200.0):
        z = np.exp(-2j * np.pi * f / rate)
        h = np.prod([(s[0] + s[1] * z + s[2] * z * z) / (s[3] + s[4] * z + s[5] * z * z) for s in sos])
        ratio = np.tan(np.pi * f / rate) / np.tan(np.pi * cutoff / rate)
        assert abs(abs(h) ** 2 - 1.0 / (1.0 + ratio ** (2 * order))) < 1e-12


def test_butter_sos_refuses_a_cutoff_outside_the_band():
    for cutoff in (0.0, -1.0, 500.0, 600.0):
        with pytest.raises(ValueError, match="Nyquist"):
            lowpass.butter_sos(4, cutoff, 1000.0)


@pytest.mark.parametrize("order", [1, 2, 3, 4, 7, 12])
def test_filtfilt_is_scipys_sosfiltfilt(order):
    rng = np.random.default_rng(10 + order)
    x = np.cumsum(rng.standard_normal(5000)) + 3.0
    sos = ss.butter(order, 20.0, fs=1000.0, output="sos")
    for pad in (0, 1, 37, 4999):
        ours = lowpass.filtfilt(sos, x, pad)
        assert np.array_equal(ours, ss.sosfiltfilt(sos, x, padlen=pad)), pad
    assert np.array_equal(lowpass.steady_state(sos), ss.sosfilt_zi(sos))


def test_filtfilt_filters_each_column_as_alone():
    """A 2-D signal's columns, filtered side by side, are each the 1-D result, bit for bit."""
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal((3000, 5)), axis=0)
    sos = lowpass.butter_sos(4, 12.0, 1000.0)
    for pad in (0, 1, 250):
        both = lowpass.filtfilt(sos, x, pad)
        assert both.shape == x.shape
        for j in range(x.shape[1]):
            assert np.array_equal(both[:, j], ss.sosfiltfilt(sos, x[:, j], padlen=pad)), (pad, j)


def test_filtfilt_keeps_a_constant_and_its_input():
    """A constant passes unchanged (unit DC gain, started from the steady state); the input is not modified."""
    x = np.full(400, 2.5)
    before = x.copy()
    y = lowpass.filtfilt(lowpass.butter_sos(4, 10.0, 1000.0), x, 50)
    assert np.allclose(y, 2.5, rtol=0, atol=1e-12)
    assert np.array_equal(x, before)
    with pytest.raises(ValueError, match="pad"):
        lowpass.filtfilt(lowpass.butter_sos(4, 10.0, 1000.0), x, 400)


@pytest.mark.parametrize("nperseg", [8, 1000, 4096, 30000, 40000])
def test_welch_is_scipys(nperseg):
    rng = np.random.default_rng(nperseg)
    x = rng.standard_normal((30000, 2))
    x[:, 0] += 5.0 * np.sin(0.01 * np.arange(30000)) + 1e-3 * np.arange(30000)
    f_ours, p_ours = lowpass.welch(x, 1000.0, nperseg)
    with warnings.catch_warnings():  # scipy warns when nperseg exceeds the length, and shortens it
        warnings.simplefilter("ignore", UserWarning)
        f_scipy, p_scipy = ss.welch(x, fs=1000.0, window="blackmanharris", nperseg=nperseg, detrend="linear", axis=0)
    assert np.array_equal(f_ours, f_scipy)
    assert np.max(np.abs(p_ours - p_scipy) / p_scipy.max(axis=0)) < 1e-12


def test_blackman_harris_is_scipys():
    for n in (8, 9, 1024):
        assert np.allclose(lowpass.blackman_harris(n), ss.get_window("blackmanharris", n), rtol=0, atol=1e-15)


def test_identify_does_not_import_scipy_signal():
    """The point of the module: a plain identify leaves scipy.signal (0.55 s of import) out.  A real process,
    since this one has imported it already."""
    code = (
        "import sys, io, contextlib\n"
        "from wmrid.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try: main(['identify', 'sample_logs/paper_sinusoid.csv', '--format', 'json'])\n"
        "    except SystemExit as e: assert e.code in (0, None), e.code\n"
        "print('scipy.signal' in sys.modules)\n"
    )
    root = ROOT_DIR
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.stdout.strip() == "False", out.stderr
