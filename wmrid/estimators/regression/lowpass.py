"""Zero-phase Butterworth low-pass filtering and Welch's power spectrum: the signal processing every ``wmrid
identify`` runs (IDIM's regression and the timing check, :mod:`wmrid.estimators.regression.idim_rows`).

Why here and not :mod:`scipy.signal`: importing ``scipy.signal`` takes 0.55 s on the 2-core machine wmrid is
benchmarked on (scipy 1.17 rewrites some 800 docstrings at import, and loads scipy.stats, interpolate and
optimize with it), a quarter of ``wmrid identify`` on a 10-minute bag, for three functions.  They are written
here to scipy's definitions, step for step, and ``tests/unit/estimators/test_lowpass.py`` checks them against
scipy.signal:

* :func:`butter_sos` = ``scipy.signal.butter(order, cutoff, fs=rate, output="sos")``: the analog Butterworth
  prototype (poles -exp(i pi m / 2N), m = -N+1, -N+3, ..., N-1), the cutoff pre-warped (2 fs' tan(pi Wn / fs'),
  fs' = 2, Wn the cutoff over the Nyquist frequency), the bilinear transform (zeros at z = -1), and second-order
  sections paired as scipy's ``zpk2sos`` pairs them by default ("nearest": the pole closest to the unit circle
  goes to the last section with the zeros nearest it; the gain in the first section).  Identical to scipy's
  sections (bit for bit on the orders and cutoffs the tests try).
* :func:`filtfilt` = ``scipy.signal.sosfiltfilt(sos, x, padlen=pad)``: odd extension of ``pad`` samples at each
  end, the filter run forward and backward from the steady state of a step (``sosfilt_zi``), the direct form II
  transposed recursion of ``scipy.signal.sosfilt`` in :func:`_filtfilt_columns` (numba, the same operations in the
  same order, the columns of a 2-D signal side by side).
* :func:`welch` = ``scipy.signal.welch(x, fs, window="blackmanharris", nperseg, detrend="linear", axis=0)``
  (half-overlapping segments, periodic 4-term Blackman-Harris window, a least-squares line removed from each
  segment, one-sided density); equal to rounding (the tests: 1e-9 relative).
"""

from __future__ import annotations

import numpy as np

from wmrid.core.jit import kernel

#: Blackman-Harris 4-term window coefficients (minimum 4-term, sidelobes below -92 dB), as scipy's.
BLACKMAN_HARRIS = (0.35875, 0.48829, 0.14128, 0.01168)


def butter_sos(order: int, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Second-order sections (n_sections, 6) [b0 b1 b2 1 a1 a2] of a digital Butterworth low-pass.

    order : 1..; cutoff_hz : the -3 dB frequency, 0 < cutoff_hz < rate_hz / 2; rate_hz : the sample rate.
    Raises ValueError for a cutoff outside (0, Nyquist).
    """
    wn = np.asarray(float(cutoff_hz), dtype=np.float64) / (float(rate_hz) / 2)
    if not 0.0 < wn < 1.0:
        raise ValueError(f"the cutoff {cutoff_hz!r} Hz must be above 0 and below the Nyquist frequency {rate_hz / 2:g}")
    n = int(order)
    fs = 2.0
    warped = float(2 * fs * np.tan(np.pi * wn / fs))
    m = np.arange(-n + 1, n, 2, dtype=np.float64)
    poles = -np.exp(1j * np.pi * m / (2 * n)) * warped  # the prototype's poles moved to the warped cutoff
    gain = 1.0 * warped**n
    fs2 = 2.0 * fs  # bilinear transform at fs = 2
    z_poles = (fs2 + poles) / (fs2 - poles)
    gain = gain * np.real(1.0 / np.prod(fs2 - poles))
    zeros = -np.ones(n)
    return _pair_sections(zeros, z_poles, float(gain))


def _pair_sections(zeros: np.ndarray, poles: np.ndarray, gain: float) -> np.ndarray:
    """Sections of a real digital filter given by zeros, poles and gain, paired "nearest" (see the module)."""
    n_sections = (max(len(poles), len(zeros)) + 1) // 2
    if len(poles) % 2 == 1:  # an odd count: a pole and a zero at the origin make it even
        poles = np.concatenate((poles, [0.0]))
        zeros = np.concatenate((zeros, [0.0]))
    zeros = np.concatenate(_one_of_each_pair(zeros))
    poles = np.concatenate(_one_of_each_pair(poles))
    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):  # the pole closest to the unit circle goes last
        i = _closest_to_circle(poles)
        p1 = poles[i]
        poles = np.delete(poles, i)
        real_left = int(np.isreal(poles).sum())
        if np.isreal(p1) and real_left == 0:  # the last real pole: with the nearest real zero
            j = _nearest(zeros, p1, "real")
            sos[si] = _section([zeros[j], 0], [p1, 0])
            zeros = np.delete(zeros, j)
        elif len(poles) + 1 == len(zeros) and not np.isreal(p1) and real_left == 1 and np.isreal(zeros).sum() == 1:
            j = _nearest(zeros, p1, "complex")  # one real pole and one real zero left: a complex zero pair here
            sos[si] = _section([zeros[j], zeros[j].conj()], [p1, p1.conj()])
            zeros = np.delete(zeros, j)
        else:
            if np.isreal(p1):
                real = np.flatnonzero(np.isreal(poles))
                k = real[_closest_to_circle(poles[real])]
                p2 = poles[k]
                poles = np.delete(poles, k)
            else:
                p2 = p1.conj()
            if not len(zeros):
                sos[si] = _section([], [p1, p2])
                continue
            j = _nearest(zeros, p1, "any")
            z1 = zeros[j]
            zeros = np.delete(zeros, j)
            if not np.isreal(z1):
                sos[si] = _section([z1, z1.conj()], [p1, p2])
            elif len(zeros):
                j = _nearest(zeros, p1, "real")
                sos[si] = _section([z1, zeros[j]], [p1, p2])
                zeros = np.delete(zeros, j)
            else:
                sos[si] = _section([z1], [p1, p2])
    sos[0, :3] *= gain
    return sos


def _closest_to_circle(p: np.ndarray) -> int:
    return int(np.argmin(np.abs(1 - np.abs(p))))


def _nearest(values: np.ndarray, to: complex, which: str) -> int:
    """Index of the entry of ``values`` nearest ``to`` among the real ones, the complex ones, or any."""
    order = np.argsort(np.abs(values - to))
    if which == "any":
        return int(order[0])
    real = np.isreal(values[order])
    return int(order[np.flatnonzero(real if which == "real" else ~real)[0]])


def _one_of_each_pair(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(complex, real): one of each complex-conjugate pair (positive imaginary part, the mean of the pair's
    two values), ordered by real part; the real values (within 100 eps) ordered."""
    z = np.atleast_1d(np.asarray(z))
    if z.size == 0:
        return z, z
    tol = 100 * np.finfo((1.0 * z).dtype).eps
    z = z[np.lexsort((abs(z.imag), z.real))]
    is_real = abs(z.imag) <= tol * abs(z)
    real = z[is_real].real
    if len(real) == len(z):
        return np.array([]), real
    z = z[~is_real]
    upper, lower = z[z.imag > 0], z[z.imag < 0]
    if len(upper) != len(lower):
        raise ValueError("a complex value has no conjugate")
    same_real = np.diff(upper.real) <= tol * abs(upper[:-1])  # runs of equal real part: by |imag| within
    edges = np.diff(np.concatenate(([0], same_real, [0])))
    for start, stop in zip(np.flatnonzero(edges > 0), np.flatnonzero(edges < 0) + 1, strict=True):
        for run in (upper[start:stop], lower[start:stop]):
            run[...] = run[np.lexsort([abs(run.imag)])]
    if np.any(abs(upper - lower.conj()) > tol * abs(lower)):
        raise ValueError("a complex value has no conjugate")
    return (upper + lower.conj()) / 2, real


def _section(zeros: list, poles: list) -> np.ndarray:
    """[b0 b1 b2 a0 a1 a2] of one section with unit gain, right-aligned as scipy's _single_zpksos."""
    out = np.zeros(6)
    b, a = _poly(zeros), _poly(poles)
    out[3 - len(b) : 3] = b
    out[6 - len(a) : 6] = a
    return out


def _poly(roots: list) -> np.ndarray:
    """Coefficients of prod (x - r), highest power first; real when the roots come in conjugate pairs."""
    r = np.atleast_1d(np.asarray(roots))
    if r.shape[0] == 0:
        return np.asarray([1.0])
    a = np.ones((1,), dtype=r.dtype)
    one = np.ones_like(r[0])
    for root in r:
        a = np.convolve(a, np.stack((one, -root)), mode="full")
    if np.iscomplexobj(a):
        im = np.asarray(r, dtype=np.complex128).imag
        if np.all(np.sort(im) == np.sort(-im)):
            a = np.real(a).copy()
    return a


def steady_state(sos: np.ndarray) -> np.ndarray:
    """(n_sections, 2) states of the sections after a unit step has settled (``scipy.signal.sosfilt_zi``)."""
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s in range(sos.shape[0]):
        b, a = sos[s, :3], sos[s, 3:]
        if a[0] != 1.0:
            b, a = b / a[0], a / a[0]
        companion = np.zeros((2, 2))  # of the denominator: first row -a[1:] / a[0], ones below the diagonal
        companion[0] = -a[1:] / a[0]
        companion[1, 0] = 1.0
        zi[s] = scale * np.linalg.solve(np.eye(2) - companion.T, b[1:] - a[1:] * b[0])
        scale *= np.sum(b) / np.sum(a)
    return zi


@kernel
def _filtfilt_columns(
    sos, zi, y
):  # pragma: no cover - compiled; tests/unit/estimators/test_lowpass.py compares it with scipy.signal
    """Each column of y (m, c) run forward, then backward, through the sections in place: the direct form II
    transposed recursion of ``scipy.signal.sosfilt``, each pass started from the steady state zi (n_sections, 2)
    times the pass's first value.  The columns go side by side, row by row: their recursions are independent, so
    the processor overlaps them (one column's recursion waits on its previous sample)."""
    n_sections = sos.shape[0]
    m, c = y.shape
    z = np.empty((n_sections, 2, c))
    for backward in range(2):
        first = m - 1 if backward else 0
        for s in range(n_sections):
            for j in range(c):
                z[s, 0, j] = zi[s, 0] * y[first, j]
                z[s, 1, j] = zi[s, 1] * y[first, j]
        for step in range(m):
            i = m - 1 - step if backward else step
            for j in range(c):
                x_cur = y[i, j]
                for s in range(n_sections):
                    x_new = sos[s, 0] * x_cur + z[s, 0, j]
                    z[s, 0, j] = sos[s, 1] * x_cur - sos[s, 4] * x_new + z[s, 1, j]
                    z[s, 1, j] = sos[s, 2] * x_cur - sos[s, 5] * x_new
                    x_cur = x_new
                y[i, j] = x_cur


def filtfilt(sos: np.ndarray, x: np.ndarray, pad: int) -> np.ndarray:
    """x (n,) or each column of x (n, c) filtered forward and backward by ``sos`` (zero phase, the magnitude squared),
    a new array of x's shape.

    pad : samples of odd extension at each end (0 <= pad < n), dropped again from the result.
    """
    x = np.asarray(x, dtype=np.float64)
    if not 0 <= pad < len(x):
        raise ValueError(f"pad {pad} must be at least 0 and below the signal's length {len(x)}")
    columns = x.reshape(len(x), -1)
    y = np.empty((len(x) + 2 * pad, columns.shape[1]))
    y[pad : pad + len(x)] = columns
    return filtfilt_extended(sos, y, pad).reshape(x.shape)


def filtfilt_extended(sos: np.ndarray, y: np.ndarray, pad: int) -> np.ndarray:
    """:func:`filtfilt` in place, for a caller that wrote the signal (n, c) into y[pad : pad + n] of y (n + 2 pad, c),
    float64, C order: the first and last ``pad`` rows are overwritten by the odd extension (2 x[0] - x[pad..1] before,
    2 x[-1] - x[-2..-pad-1] after); returns the filtered signal, the view y[pad : pad + n]."""
    n = len(y) - 2 * pad
    if not 0 <= pad < n:
        raise ValueError(f"pad {pad} must be at least 0 and below the signal's length {n}")
    if pad:
        y[:pad] = 2 * y[pad : pad + 1] - y[2 * pad : pad : -1]
        y[pad + n :] = 2 * y[pad + n - 1 : pad + n] - y[pad + n - 2 : n - 2 : -1]
    sos = np.ascontiguousarray(sos, dtype=np.float64)
    _filtfilt_columns(sos, steady_state(sos), y)
    return y[pad : pad + n]


def blackman_harris(n: int) -> np.ndarray:
    """The periodic 4-term Blackman-Harris window of n samples (for spectra, as ``get_window``'s default)."""
    k = 2.0 * np.pi * np.arange(n) / n
    a0, a1, a2, a3 = BLACKMAN_HARRIS
    return a0 - a1 * np.cos(k) + a2 * np.cos(2 * k) - a3 * np.cos(3 * k)


def welch(x: np.ndarray, rate_hz: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """(freq (nperseg // 2 + 1,) Hz, psd (nperseg // 2 + 1, c) per Hz) of each column of x (n, c), by Welch.

    Segments of ``nperseg`` samples (at most n) starting every nperseg - nperseg // 2 samples, each with its
    least-squares line removed and the Blackman-Harris window applied; the one-sided density, averaged.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    nperseg = min(int(nperseg), n)
    hop = nperseg - nperseg // 2
    count = max(1, (n - nperseg // 2) // hop)
    win = blackman_harris(nperseg)
    ramp = np.arange(nperseg, dtype=np.float64)
    basis = np.column_stack((ramp - ramp.mean(), np.ones(nperseg)))
    projector = np.linalg.pinv(basis)  # (2, nperseg): line fit of a segment
    psd = np.zeros((nperseg // 2 + 1, x.shape[1]))
    for p in range(count):
        seg = x[p * hop : p * hop + nperseg]
        seg = seg - basis @ (projector @ seg)
        psd += np.abs(np.fft.rfft(seg * win[:, None], axis=0)) ** 2
    psd /= count * rate_hz * float(np.sum(win * win))
    psd[1 : -1 if nperseg % 2 == 0 else None] *= 2.0
    return np.fft.rfftfreq(nperseg, 1.0 / rate_hz), psd
