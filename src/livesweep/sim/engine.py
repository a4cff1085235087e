"""The simulation engine: one augmented LTI system, discretised exactly, stepped on a fine grid.

Signal path (every block linear)::

    u_cmd --(pilot feedback)--> u_logged --delay tau_i--> input chains --> vehicle (+ gusts)
          --> y_vehicle --> output chains --> y_dyn --(sampling, skew)--> sensors

* Input chains are the actuator effects of each input (series, in the order given).
* The vehicle carries the gust states (first-order Gauss-Markov turbulence driven by white noise).
* Output chains are the structural-mode effects of each output.

Discretisation on the grid ``dt``: first-order hold for the (delayed) control inputs and
zero-order hold for the white noise, both through the exact matrix exponential. A first-order
hold reproduces a smooth input with a magnitude error of about ``(w dt)^2 / 12`` and no phase
error (0.002 dB at 20 rad/s on a 400 Hz grid). Delays and sensor skews are fractional shifts by
linear interpolation on the grid: magnitude error at most ``(w dt)^2 / 8`` (0.003 dB at 20 rad/s,
400 Hz), phase error of third order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError
from livesweep.lti import discretize_foh, discretize_zoh
from livesweep.effects import Effect
from livesweep.sim.models import LinearVehicleModel

__all__ = ["Turbulence", "PilotLoop", "AugmentedSystem", "augment", "discretize", "step", "shift"]


@dataclass(frozen=True)
class Turbulence:
    """Coloured process noise: first-order Gauss-Markov gusts on the model's gust inputs.

    Each gust ``g`` obeys ``g' = -g/T + sigma sqrt(2/T) eta`` with ``eta`` unit white noise, so
    its standard deviation is ``sigma`` and its spectrum rolls off above ``1/T`` rad/s.

    Parameters
    ----------
    sigmas : tuple of float
        Standard deviation of each gust, in the model's gust units (``v_g`` ft/s, ``p_g`` rad/s).
    correlation_time_s : float
        T [s] (about L/U for a Dryden-like scale length L).
    """

    sigmas: tuple[float, ...]
    correlation_time_s: float = 2.0

    def __post_init__(self):
        if self.correlation_time_s <= 0 or not np.isfinite(self.correlation_time_s):
            raise ConfigError(f"turbulence correlation_time_s must be > 0, got {self.correlation_time_s!r}")
        if any((not np.isfinite(s)) or s < 0 for s in self.sigmas):
            raise ConfigError(f"turbulence sigmas must be finite and >= 0, got {self.sigmas!r}")


@dataclass(frozen=True)
class PilotLoop:
    """A stabilising pilot (or SCAS) adding ``gain * y_vehicle(t - delay_s)`` to an input command.

    Parameters
    ----------
    gains : tuple of (input, output, gain)
        ``gain`` in input units per output unit (e.g. deg aileron per deg of roll).
    delay_s : float
        Pilot reaction delay [s] (rounded to the grid; at least one step).
    """

    gains: tuple[tuple[str, str, float], ...]
    delay_s: float = 0.2


@dataclass(frozen=True)
class AugmentedSystem:
    """``X' = A X + B u_p + Bw eta``, ``y_dyn = C X + D u_p``, ``y_vehicle = Cv X + Dv u_p``.

    ``u_p`` is the delayed command (``delays_s`` per input), ``eta`` unit white noise.
    """

    A: np.ndarray
    B: np.ndarray
    Bw: np.ndarray
    C: np.ndarray
    D: np.ndarray
    Cv: np.ndarray
    Dv: np.ndarray
    delays_s: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]


def _series(s1, s2):
    """State-space series connection: output of s1 feeds s2. Each s = (A, B, C, D)."""
    A1, B1, C1, D1 = s1
    A2, B2, C2, D2 = s2
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    B = np.vstack([B1, B2 @ D1])
    C = np.hstack([D2 @ C1, C2])
    D = D2 @ D1
    return A, B, C, D


def _identity_ss(m):
    return np.zeros((0, 0)), np.zeros((0, m)), np.zeros((m, 0)), np.eye(m)


def _block_diag(mats):
    """Block-diagonal matrix that keeps zero-sized blocks' shapes (scipy's drops them)."""
    rows = sum(m.shape[0] for m in mats)
    cols = sum(m.shape[1] for m in mats)
    out = np.zeros((rows, cols))
    r = c = 0
    for m in mats:
        out[r:r + m.shape[0], c:c + m.shape[1]] = m
        r += m.shape[0]
        c += m.shape[1]
    return out


def _block_diag_ss(systems):
    return tuple(_block_diag([s[i] for s in systems]) for i in range(4))


def _chain(blocks):
    s = _identity_ss(1)
    for blk in blocks:
        s = _series(s, blk)
    return s


def augment(model: LinearVehicleModel, effects: list[Effect] = (), turbulence: Turbulence | None = None) -> AugmentedSystem:
    """Build the augmented system of ``model`` with the dynamic ``effects`` and gust states.

    Parameters
    ----------
    model : LinearVehicleModel
    effects : list of Effect
        Those with ``dynamics`` (delays, actuators, filters, structural modes) change the
        dynamics; the others are sensor effects handled at sampling.
    turbulence : Turbulence or None

    Returns
    -------
    AugmentedSystem
    """
    n_in, n_out, n_g = len(model.inputs), len(model.outputs), len(model.gust_names)
    in_blocks = {name: [] for name in model.inputs}
    out_blocks = {name: [] for name in model.outputs}
    delays = np.array(model.input_delays_s, dtype=float)
    for eff in effects:
        if eff.acts_on == "input":
            i = model.input_index(eff.input)
        else:
            model.output_index(eff.output)
        if eff.dynamics == "delay":
            delays[i] += eff.delay_s
        elif eff.dynamics == "input_block":
            in_blocks[eff.input].append(eff.state_space())
        elif eff.dynamics == "output_block":
            out_blocks[eff.output].append(eff.state_space())

    # Stage 1: input chains, with the gust noise passed straight through.
    inputs_stage = _block_diag_ss([_chain(in_blocks[n]) for n in model.inputs] + [_identity_ss(n_g)])

    # Stage 2: vehicle with gust states.
    if turbulence is not None and len(turbulence.sigmas) != n_g:
        raise ConfigError(
            f"turbulence needs {n_g} sigmas for model {model.name!r} ({', '.join(model.gust_names)}), "
            f"got {len(turbulence.sigmas)}"
        )
    n = model.F.shape[0]
    T = turbulence.correlation_time_s if turbulence else 1.0
    sig = np.asarray(turbulence.sigmas if turbulence else np.zeros(n_g), dtype=float)
    Ag = -np.eye(n_g) / T
    Bg = np.diag(sig * np.sqrt(2.0 / T))
    Av = np.block([[model.F, model.gust_F], [np.zeros((n_g, n)), Ag]])
    Bv = np.block([[model.G, np.zeros((n, n_g))], [np.zeros((n_g, n_in)), Bg]])
    Cv = np.hstack([model.H, model.gust_H])
    Dv = np.hstack([model.J, np.zeros((n_out, n_g))])
    front = _series(inputs_stage, (Av, Bv, Cv, Dv))

    # Stage 3: output chains.
    outputs_stage = _block_diag_ss([_chain(out_blocks[n]) for n in model.outputs])
    A, B, C, D = _series(front, outputs_stage)
    n_front = front[0].shape[0]
    n_tot = A.shape[0]
    Cveh = np.hstack([front[2], np.zeros((n_out, n_tot - n_front))])
    if np.any(D[:, n_in:] != 0):
        raise AssertionError("gust noise must not feed through to outputs")
    return AugmentedSystem(
        A=A, B=B[:, :n_in], Bw=B[:, n_in:], C=C, D=D[:, :n_in],
        Cv=Cveh, Dv=front[3][:, :n_in], delays_s=delays,
        input_names=model.inputs, output_names=model.outputs,
    )


def discretize(system: AugmentedSystem, dt: float):
    """Exact discretisation: FOH for the control input, ZOH for the white noise.

    Returns
    -------
    Phi, Gamma0, Gamma1, Gammaw : ndarray
        ``X[k+1] = Phi X[k] + Gamma0 u[k] + Gamma1 u[k+1] + Gammaw eta[k]``.
    """
    Phi, G0, G1 = discretize_foh(system.A, system.B, dt)
    return Phi, G0, G1, discretize_zoh(system.A, system.Bw, dt)


def shift(x: np.ndarray, delay_samples: float) -> np.ndarray:
    """``x`` delayed by a fractional number of samples (linear interpolation, first value held).

    Parameters
    ----------
    x : ndarray, shape (N,) or (N, m)
    delay_samples : float
        Delay in samples; negative advances (last value held at the end).
    """
    x = np.asarray(x, dtype=float)
    k = np.arange(x.shape[0], dtype=float) - delay_samples
    if x.ndim == 1:
        return np.interp(k, np.arange(x.shape[0]), x)
    return np.column_stack([np.interp(k, np.arange(x.shape[0]), x[:, j]) for j in range(x.shape[1])])


def step(system: AugmentedSystem, dt: float, u_cmd: np.ndarray, eta: np.ndarray,
         pilot: PilotLoop | None = None):
    """Run the augmented system over the grid ``k dt``, starting at rest.

    The pilot's feedback at step ``j`` uses outputs from ``j - lag`` (``lag`` >= 1 steps), so the
    grid is processed in blocks of ``lag`` steps: the feedback, the delayed inputs and the
    drive terms of a block are vectorised and only the state recursion runs step by step.

    Parameters
    ----------
    system : AugmentedSystem
    dt : float
        Grid step [s].
    u_cmd : ndarray, shape (N, n_in)
        Commanded inputs on the grid (input units).
    eta : ndarray, shape (N, n_w)
        Unit-intensity white noise samples (variance ``1/dt``).
    pilot : PilotLoop or None
        Feedback ``gain * y_vehicle(t - delay)`` added to the command.

    Returns
    -------
    u_logged : ndarray, shape (N, n_in)
        The command as logged (including pilot feedback).
    y_dyn : ndarray, shape (N, n_out)
        Outputs after the output chains, before sensor effects.
    """
    Phi, G0, G1, Gw = discretize(system, dt)
    N, m = u_cmd.shape
    n = Phi.shape[0]
    K = _pilot_gains(system, pilot)
    lag = N if pilot is None else max(1, int(round(pilot.delay_s / dt)))
    d = system.delays_s / dt
    lo = np.floor(d).astype(int)          # u_p[j] = a u_log[j - lo] + b u_log[j - lo - 1]
    b = d - lo
    a = 1.0 - b
    cols = np.arange(m)
    u_log = np.array(u_cmd, dtype=float)
    u_p = np.zeros((N, m))
    X = np.zeros((N, n))
    yv = np.zeros((N, len(system.output_names)))
    noise_drive = eta @ Gw.T
    PhiT = Phi.T
    for j0 in range(0, N, lag):
        j1 = min(N, j0 + lag)
        if pilot is not None and j0 >= lag:
            u_log[j0:j1] += yv[j0 - lag:j1 - lag] @ K.T
        j = np.arange(j0, j1)[:, None]
        u_p[j0:j1] = a * u_log[np.maximum(j - lo, 0), cols] + b * u_log[np.maximum(j - lo - 1, 0), cols]
        k0 = max(j0, 1)
        drive = u_p[k0 - 1:j1 - 1] @ G0.T + u_p[k0:j1] @ G1.T + noise_drive[k0 - 1:j1 - 1]
        x = X[k0 - 1]
        for i, k in enumerate(range(k0, j1)):
            x = x @ PhiT + drive[i]
            X[k] = x
        if pilot is not None:
            yv[j0:j1] = X[j0:j1] @ system.Cv.T + u_p[j0:j1] @ system.Dv.T
    y_dyn = X @ system.C.T + u_p @ system.D.T
    return u_log, y_dyn


def _pilot_gains(system: AugmentedSystem, pilot: PilotLoop | None) -> np.ndarray:
    K = np.zeros((len(system.input_names), len(system.output_names)))
    for inp, out, gain in (pilot.gains if pilot else ()):
        if inp not in system.input_names or out not in system.output_names:
            raise ConfigError(f"pilot gain names unknown input/output {inp!r}/{out!r}")
        K[system.input_names.index(inp), system.output_names.index(out)] += float(gain)
    return K
