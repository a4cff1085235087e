"""Array-first entry points: frequency responses and transfer-function fits from numpy arrays.

For notebooks and scripts that already hold their data: no case file, no log, no folder.

Examples
--------
A first-order roll response ``p/da = 5 / (s + 2)`` sampled at 50 Hz, swept by noise:

>>> import numpy as np, scipy.signal
>>> import livesweep
>>> rng = np.random.default_rng(0)
>>> t = np.arange(0, 300, 0.02)
>>> da = rng.standard_normal(t.size)
>>> p = scipy.signal.lsim(([5.0], [1.0, 2.0]), da, t)[1]
>>> frs = livesweep.frequency_response(da, p, sample_rate_hz=50.0, band_rad_s=(0.5, 20.0),
...                                    input_names="da", output_names="p")
>>> fit = livesweep.fit_transfer_function(frs.pair("p", "da"), denominator="(1/T)", delay=False)
>>> round(fit.parameters["gain"], 1), round(fit.parameters["1/T"], 1)
(5.0, 2.0)
"""

from __future__ import annotations

import numpy as np

from livesweep.errors import ConfigError

__all__ = ["frequency_response", "fit_transfer_function"]


def _signals(x, names, default: str, what: str):
    """``x`` as (n, N) float rows with n names; ConfigError naming ``what`` on a bad shape."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise ConfigError(f"{what}: expected shape (n_signals, n_samples) or (n_samples,), got {np.shape(x)}")
    if names is None:
        names = [default] if arr.shape[0] == 1 else [f"{default}{k}" for k in range(arr.shape[0])]
    elif isinstance(names, str):
        names = [names]
    names = [str(n) for n in names]
    if len(names) != arr.shape[0]:
        raise ConfigError(f"{what}: {arr.shape[0]} signal(s) but {len(names)} name(s) {names}")
    return arr, names


def frequency_response(inputs, outputs, *, sample_rate_hz: float, band_rad_s, input_names=None, output_names=None,
                       references=None, windows_s=None, valid=None, n_freq: int = 150):
    """Frequency responses of outputs to inputs from uniformly sampled arrays.

    The same estimate ``livesweep identify`` makes: Hann windows of several lengths with 80 %
    overlap, a composite over them, MISO conditioning when there are several inputs, coherence
    and random error per point (method: ``docs`` of the repository, "Frequency responses").

    Parameters
    ----------
    inputs : array_like, shape (n_inputs, N) or (N,)
        Measured inputs (controls), one row per input, in input units.
    outputs : array_like, shape (n_outputs, N) or (N,)
        Measured responses, same samples.
    sample_rate_hz : float
        Sample rate of both [Hz].
    band_rad_s : (float, float)
        Frequency band of the result [rad/s].
    input_names, output_names : str or sequence of str, optional
        Default ``u`` / ``y`` (``u0``, ``u1``, ... when several).
    references : array_like, shape (n_inputs, N), optional
        One exogenous reference per input (a closed-loop test point's logged injection); the
        responses are then formed through it, free of the feedback's bias.
    windows_s : sequence of float, optional
        Window lengths [s]; default five, spread geometrically from the band and the record length.
    valid : array_like of bool, shape (N,), optional
        False in data gaps (windows touching them are skipped). Non-finite samples must be
        marked here; otherwise they are an error.
    n_freq : int
        Points of the log-spaced frequency grid.

    Returns
    -------
    FrequencyResponseSet
        ``.pair(output, input)`` gives one :class:`~livesweep.spectral.response.FrequencyResponse`;
        arrays are read-only; ``.to_frd()`` converts to python-control.

    Raises
    ------
    ConfigError
        Shapes that do not match, non-finite samples outside ``valid``, a band or windows the
        record cannot support (one line naming the argument).
    """
    from livesweep.spectral.analysis import analyze

    u, in_names = _signals(inputs, input_names, "u", "inputs")
    y, out_names = _signals(outputs, output_names, "y", "outputs")
    rows, names = [u, y], [*in_names, *out_names]
    ref_names = None
    if references is not None:
        r, ref_names = _signals(references, [f"{n}_ref" for n in in_names], "r", "references")
        rows.append(r)
        names += ref_names
    if len({a.shape[1] for a in rows}) != 1:
        raise ConfigError("inputs, outputs" + (", references" if references is not None else "")
                          + f" must have the same number of samples, got {[a.shape[1] for a in rows]}")
    if len(set(names)) != len(names):
        raise ConfigError(f"signal names must be distinct, got {names}")
    x = np.vstack(rows)
    ok = None if valid is None else np.asarray(valid, bool)
    if ok is not None and ok.shape != (x.shape[1],):
        raise ConfigError(f"valid: expected shape ({x.shape[1]},), got {ok.shape}")
    bad = ~np.isfinite(x)
    used = bad if ok is None else bad[:, ok]
    if used.any():
        k = int(np.argmax(used.any(axis=1)))
        raise ConfigError(f"{names[k]}: {int(used[k].sum())} non-finite sample(s) outside the gaps; "
                          "mark gaps with valid=")
    x = np.where(bad, 0.0, x)
    x = x - (x[:, ok].mean(axis=1, keepdims=True) if ok is not None else x.mean(axis=1, keepdims=True))
    return analyze(x, names, float(sample_rate_hz), in_names, out_names, tuple(band_rad_s), valid=ok,
                   windows_s=windows_s, n_freq=n_freq, references=ref_names).best


def fit_transfer_function(response, *, denominator: str, numerator: str = "", delay: bool = True,
                          band_rad_s=None, name: str | None = None, tau_max_s: float = np.inf):
    """Fit ``gain * N(s) / D(s) * exp(-tau s)`` to one pair's frequency response.

    Parameters
    ----------
    response : FrequencyResponse
        One pair (``frs.pair("p", "da")``).
    denominator, numerator : str
        Factors in the case-file shorthand: ``"(1/T)"`` a first-order factor ``s + 1/T``,
        ``"[zeta, w]"`` a second-order ``s^2 + 2 zeta w s + w^2``, ``"s"`` a free integrator or
        differentiator, numbers for fixed values (``"(0) [0.7, w]"``).
    delay : bool
        Fit a delay ``tau >= 0`` [s].
    band_rad_s : (float, float), optional
        Fitting band [rad/s]; default the coherent band of the pair (gamma^2 >= 0.6, the default criteria).
    name : str, optional
        Default ``"<output>/<input>"``.
    tau_max_s : float
        Upper bound of the delay [s].

    Returns
    -------
    FittedTransferFunction
        Gain, zeros, poles, delay, cost J and Cramer-Rao bounds; ``.to_tf()`` converts to
        python-control.
    """
    from livesweep.ident.cost import fit_points
    from livesweep.ident.transfer_function import TransferFunctionModel
    from livesweep.ident.transfer_function import fit_transfer_function as _fit

    if not hasattr(response, "H") or np.ndim(response.H) != 1:
        raise ConfigError("response: expected one pair's FrequencyResponse (use frs.pair(output, input))")
    pair = fit_points(response, band_rad_s=None if band_rad_s is None else tuple(band_rad_s))
    model = TransferFunctionModel(name or f"{response.output}/{response.input}", numerator=numerator,
                                  denominator=denominator, delay=delay)
    return _fit(pair, model, tau_max_s=tau_max_s)[0]
