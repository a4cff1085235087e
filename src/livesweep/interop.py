"""Results as python-control systems (``pip install 'livesweep[control]'``).

Each function is also a method of the result it converts: ``FrequencyResponse.to_frd()``,
``FrequencyResponseSet.to_frd()``, ``FittedTransferFunction.to_tf()``, ``StateSpaceFit.to_ss()``.
python-control is imported only when one of them is called; without it they raise an ImportError
that says how to install it.

Delays. python-control's rational systems have no exact delay. ``to_tf`` and ``to_ss`` return the
delay-free part by default (the delays are the result's ``delay_s`` / the model's input delays,
output delays and input skews) or, with ``pade_order=n``, the delays replaced by order-``n`` Pade
approximants (good to about ``omega * tau < n``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["response_to_frd", "response_set_to_frd", "transfer_function_to_tf", "state_space_to_ss"]


def _control():
    try:
        import control
    except ImportError:
        raise ImportError("python-control is not installed: pip install 'livesweep[control]' "
                          "(or pip install control)") from None
    return control


def response_to_frd(response):
    """One pair's frequency response as a SISO ``control.FrequencyResponseData``.

    Parameters
    ----------
    response : FrequencyResponse
        Its complex ``H`` (output units per input unit) at ``omega`` [rad/s]. Points where ``H``
        is not finite are left out.

    Returns
    -------
    control.FrequencyResponseData
    """
    control = _control()
    ok = np.isfinite(response.H)
    return control.frd(np.asarray(response.H)[ok], np.asarray(response.omega)[ok],
                       inputs=[response.input], outputs=[response.output])


def response_set_to_frd(response_set):
    """A MIMO set as one ``control.FrequencyResponseData`` (outputs x inputs, named).

    Parameters
    ----------
    response_set : FrequencyResponseSet
        Frequencies where any pair is not finite are left out.
    """
    control = _control()
    H = np.asarray(response_set.H)
    ok = np.all(np.isfinite(H), axis=(0, 1))
    return control.frd(H[:, :, ok], np.asarray(response_set.omega)[ok], inputs=list(response_set.inputs),
                       outputs=list(response_set.outputs))


def _pade(control, tau: float, order: int):
    num, den = control.pade(float(tau), int(order))
    return control.tf(num, den)


def transfer_function_to_tf(fit, *, pade_order: int | None = None):
    """A fitted transfer function as ``control.TransferFunction``.

    Parameters
    ----------
    fit : FittedTransferFunction
    pade_order : int, optional
        None: the rational part only, ``gain * prod(s - z) / prod(s - p)`` (multiply by
        ``exp(-s fit.delay_s)`` yourself). An integer: the delay as a Pade approximant of that order.

    Returns
    -------
    control.TransferFunction
    """
    control = _control()
    num = float(fit.gain) * np.real_if_close(np.poly(np.asarray(fit.zeros, complex)), tol=1e6)
    den = np.real_if_close(np.poly(np.asarray(fit.poles, complex)), tol=1e6)
    T = control.tf(np.real(num), np.real(den), inputs=[fit.input], outputs=[fit.output])
    if pade_order is not None and fit.delay_s > 0:
        T = control.series(_pade(control, fit.delay_s, pade_order), T)
    return T


def state_space_to_ss(fit, *, pade_order: int | None = None):
    """An identified state-space model as ``control.StateSpace`` (states, inputs, outputs named).

    ``A = M^-1 F``, ``B = M^-1 G``, ``C = H``, ``D = J`` at the fitted parameters, in the units of
    the case's model (its states', inputs' and outputs' units).

    Parameters
    ----------
    fit : StateSpaceFit
    pade_order : int, optional
        None: without delays (``fit.model.delays`` etc. hold them). An integer: each input's net
        delay (delay minus skew) and each output's delay as a Pade approximant of that order in
        series with the model (the returned system then has extra states).

    Returns
    -------
    control.StateSpace
    """
    control = _control()
    model = fit.model
    M, F, G, H, J, tau = model.matrices(fit.theta)
    A, B = np.linalg.solve(M, F), np.linalg.solve(M, G)
    sys = control.ss(A, B, H, J, states=list(model.states), inputs=list(model.inputs), outputs=list(model.outputs))
    if pade_order is None:
        return sys
    tau_in = np.asarray(tau, float) - np.asarray(model.input_skews_s(fit.theta), float)
    tau_out = np.asarray(model.output_delays_s(fit.theta), float)
    if np.any(tau_in > 0):
        din = control.append(*[control.ss(_pade(control, t, pade_order)) if t > 0 else control.ss([], [], [], [[1.0]])
                               for t in tau_in])
        sys = control.series(din, sys)
    if np.any(tau_out > 0):
        dout = control.append(*[control.ss(_pade(control, t, pade_order)) if t > 0 else control.ss([], [], [], [[1.0]])
                                for t in tau_out])
        sys = control.series(sys, dout)
    if np.any(tau_in > 0) or np.any(tau_out > 0):
        sys = control.ss(sys.A, sys.B, sys.C, sys.D, inputs=list(model.inputs), outputs=list(model.outputs))
    return sys
