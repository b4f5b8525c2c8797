"""Long series reduced for drawing, their spikes kept: :func:`decimate_for_display` (for display only, never for
computation; :mod:`wmrid.reporting.figures` draws every line through it)."""

from __future__ import annotations

import numpy as np

from wmrid.core.errors import UsageError

#: The most points any plotted line carries.
MAX_POINTS = 4000


def _bin_edges(n: int, max_points: int) -> np.ndarray:
    """Edges of the bins that :func:`decimate_for_display` reduces, over samples 1 .. n-2.

    Samples 0 and n-1 are always kept; the interior is cut into at most (max_points - 2) // 2 bins of
    equal length (the last may be shorter).  Returns edges e (nb + 1,): bin j is samples e[j]:e[j+1].
    """
    interior = n - 2
    n_bins = (max_points - 2) // 2
    size = -(-interior // n_bins)
    return np.append(np.arange(1, n - 1, size), n - 1)


def envelope_indices(y: np.ndarray, max_points: int) -> np.ndarray:
    """Sorted indices of the samples that :func:`decimate_for_display` keeps (at most max_points)."""
    n = len(y)
    if n <= max_points:
        return np.arange(n)
    edges = _bin_edges(n, max_points)
    n_bins, size = len(edges) - 1, int(edges[1] - edges[0])
    interior = y[1 : n - 1]
    pad = n_bins * size - len(interior)
    nan = np.isnan(interior)
    # NaN never wins a bin that has numbers; a bin of only NaN keeps one (a gap in the drawn line).
    low = np.concatenate([np.where(nan, np.inf, interior), np.full(pad, np.inf)]).reshape(n_bins, size)
    high = np.concatenate([np.where(nan, -np.inf, interior), np.full(pad, -np.inf)]).reshape(n_bins, size)
    start = 1 + size * np.arange(n_bins)
    keep = np.concatenate([[0], start + np.argmin(low, axis=1), start + np.argmax(high, axis=1), [n - 1]])
    return np.unique(keep)


def decimate_for_display(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """A series reduced to at most ``max_points`` samples for drawing, spikes kept.

    t, y : (n,) (y may hold NaN).  When n <= max_points both are returned as they are (as arrays).
    Otherwise the first and last samples are kept and the samples in between are cut into
    (max_points - 2) // 2 bins of consecutive samples; of each bin the samples holding its minimum
    and its maximum are kept, in their original order.  The result is a subset of the input, so the
    drawn line passes through every bin's extremes.  For display only, never for computation.
    """
    t = np.asarray(t)
    y = np.asarray(y)
    if t.ndim != 1 or y.shape != t.shape:
        raise UsageError(f"decimate_for_display needs t and y of one shape (n,), got {t.shape} and {y.shape}")
    if max_points < 4:
        raise UsageError(f"max_points must be at least 4 (first, last and one bin's min and max), got {max_points}")
    idx = envelope_indices(y, int(max_points))
    return t[idx], y[idx]
