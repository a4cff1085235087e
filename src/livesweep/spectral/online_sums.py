"""What the online estimator's running sums hold: the signal layout and a result's frozen copy of them.

One job: describe the running sums of segment cross-spectra that
:class:`~livesweep.spectral.online.OnlineSpectralEstimator` keeps, so that the estimator (which
updates them) and :class:`~livesweep.spectral.online_result.OnlineResult` (which reads them) agree
on where every signal sits. :class:`_Layout` places the drivers (inputs and references), inputs
and outputs once per estimator; :class:`_WindowSums` is the never-written copy of the sums a
result is made from; :func:`_readonly` freezes the arrays the results of one window share.
"""

from __future__ import annotations

import numpy as np


class _Layout:
    """Where the estimator's signals sit, worked out once: drivers (inputs and references, in
    signal order), inputs, outputs, and the input pairs of the input coherence."""

    __slots__ = ("drivers", "driver_rows", "inputs", "outputs", "input_rows", "pair_a", "pair_b", "pair_rows",
                 "inputs_at", "outputs_at", "input_rows_at", "driver_rows_at")

    def __init__(self, names, inputs, outputs, references):
        self.drivers = tuple(sorted({names.index(n) for n in tuple(inputs) + tuple(references)}))
        self.driver_rows = np.array(self.drivers, dtype=np.intp)
        self.inputs = np.array([names.index(n) for n in inputs], dtype=np.intp)
        self.outputs = np.array([names.index(n) for n in outputs], dtype=np.intp)
        self.input_rows = np.array([self.drivers.index(i) for i in self.inputs], dtype=np.intp)
        a, b = np.triu_indices(len(self.inputs), 1)
        self.pair_a, self.pair_b, self.pair_rows = self.inputs[a], self.inputs[b], self.input_rows[a]
        # the same, as slices where they are runs (the usual layout): views instead of copies
        self.inputs_at, self.outputs_at, self.input_rows_at, self.driver_rows_at = (
            _run(i) for i in (self.inputs, self.outputs, self.input_rows, self.driver_rows))


def _run(idx: np.ndarray):
    """``slice(a, b)`` when ``idx`` is ``a, a+1, .., b-1``, else ``idx``: indexes the same elements."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


class _WindowSums:
    """Running sums of one window's contents, as the estimator held them when a result was made.

    ``rows[d, j] = sum_k conj(X_kd) X_kj`` for every *driver* ``d`` (an input or a reference: the
    signals the responses divide by or condition on) and every signal ``j``; ``auto[j] = sum_k
    |X_kj|^2``; ``X`` the segments' transforms (for the rest of the matrix, computed only if
    ``G`` is read); ``scale`` turns sums into one-sided densities (``2 / (fs sum w^2 K)``).
    Never written: the estimator replaces its sums by new arrays instead of updating them in place.
    """

    __slots__ = ("layout", "drivers", "rows", "auto", "X", "scale")

    def __init__(self, layout, rows, auto, X, scale):
        self.layout, self.drivers = layout, layout.drivers
        self.rows, self.auto, self.X, self.scale = rows, auto, X, scale



def _readonly(a: np.ndarray) -> np.ndarray:
    """``a``, made read-only (arrays shared by the results of one window must not be written)."""
    a = np.asarray(a)
    a.setflags(write=False)
    return a
