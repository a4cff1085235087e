"""Linear vehicle models for the simulator: the XV-15 lateral-directional models of the seed.

Model structure (both flight conditions, body axes, level trim, small angles, M = I)::

    states  x = [v, p, r, phi]          v in ft/s, p and r in rad/s, phi in rad
    inputs  u = [da, dr]                aileron and rudder in deg (the seed's G is per degree)

    v'   = Yv v + Yp p + (Yr - U0) r + g phi + Yda da + Ydr dr
    p'   = Lv v + Lp p + Lr r              + Lda da + Ldr dr
    r'   = Nv v + Np p + Nr r              + Nda da + Ndr dr
    phi' = p

    u(t) enters delayed: u_i(t - tau_i), one delay per input (tau_a, tau_r).

``U0`` (true airspeed, ft/s) enters only through the kinematic ``-U0 r`` term, so ``Yr`` is the
aerodynamic derivative alone (the seed's Yr = 16.44 ft/s/rad; with Yr - U0 the Dutch roll and
roll modes come out near the transfer-function poles of Eq. 2.9, with Yr alone they do not).
``g`` (32.174 ft/s^2) enters through the gravity term ``g phi``.

Sensed outputs (what the simulator's sensors measure)::

    p    [deg/s] = 57.2958 p
    r    [deg/s] = 57.2958 r
    ay   [ft/s^2] = Yv v + Yp p + Yr r + Yda da + Ydr dr    (specific force = v' + U0 r - g phi)
    beta [deg]   = 57.2958 v / U0                          (cruise only; air-relative)
    v    [ft/s]  = v                                       (hover: reconstructed lateral velocity)
    phi  [deg]   = 57.2958 phi

Turbulence enters as gust velocities ``v_g`` (ft/s) and ``p_g`` (rad/s): the aerodynamic terms act
on the air-relative motion ``v - v_g`` and ``p - p_g``, so the gust input matrix is minus the
aerodynamic part of the v and p columns of F (and of the ay and beta output rows).

The derivative values are Tables 2.1-2.4 of the seed as mapped in ``reference/method.md`` §11
(English units; eliminated parameters are zero).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.numbers import frozen_array as _frozen

RAD2DEG = 180.0 / np.pi
G_FT_S2 = 32.174
KNOT_FT_S = 1.6878099

__all__ = [
    "LinearVehicleModel",
    "xv15_cruise",
    "xv15_hover",
    "MODELS",
    "get_model",
]


@dataclass(frozen=True)
class LinearVehicleModel:
    """A linear time-invariant vehicle ``x' = F x + G u(t - tau)``, ``y = H x + J u(t - tau)``.

    Attributes
    ----------
    name : str
        Registry name, e.g. ``"xv15-cruise"``.
    description : str
        Flight condition in words.
    states, inputs, outputs : tuple of str
        Signal names, in matrix order.
    state_units, input_units, output_units : tuple of str
        Units of each signal.
    F, G, H, J : ndarray
        System matrices (read-only). ``G`` and ``J`` are per input unit (deg).
    input_delays_s : tuple of float
        Pure time delay on each input [s].
    gust_names : tuple of str
        Names of the turbulence inputs (``v_g`` [ft/s], ``p_g`` [rad/s]).
    gust_F, gust_H : ndarray
        How the gusts enter the state and output equations.
    seed_outputs : tuple of str
        The outputs the seed identified this model from.
    derivatives : dict
        The named stability and control derivatives the matrices were built from.
    constants : dict
        Trim constants (``U0_ft_s``, ``g_ft_s2``).
    """

    name: str
    description: str
    states: tuple[str, ...]
    state_units: tuple[str, ...]
    inputs: tuple[str, ...]
    input_units: tuple[str, ...]
    outputs: tuple[str, ...]
    output_units: tuple[str, ...]
    F: np.ndarray
    G: np.ndarray
    H: np.ndarray
    J: np.ndarray
    input_delays_s: tuple[float, ...]
    gust_names: tuple[str, ...]
    gust_F: np.ndarray
    gust_H: np.ndarray
    seed_outputs: tuple[str, ...]
    derivatives: dict = field(default_factory=dict)
    constants: dict = field(default_factory=dict)

    def output_index(self, name: str) -> int:
        """Index of output ``name``; ConfigError listing the outputs when unknown."""
        try:
            return self.outputs.index(name)
        except ValueError:
            raise ConfigError(
                f"unknown output {name!r} for model {self.name!r}; outputs are {', '.join(self.outputs)}"
            ) from None

    def input_index(self, name: str) -> int:
        """Index of input ``name``; ConfigError listing the inputs when unknown."""
        try:
            return self.inputs.index(name)
        except ValueError:
            raise ConfigError(
                f"unknown input {name!r} for model {self.name!r}; inputs are {', '.join(self.inputs)}"
            ) from None

    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of F [rad/s], sorted by real part then imaginary part."""
        return np.sort_complex(np.linalg.eigvals(self.F))

    def frequency_response(self, omega_rad_s) -> np.ndarray:
        """Exact frequency response including the input delays.

        Parameters
        ----------
        omega_rad_s : array_like
            Frequencies [rad/s].

        Returns
        -------
        ndarray, complex, shape (n_outputs, n_inputs, n_freq)
            ``T(jw) = [H (jw I - F)^-1 G + J] diag(exp(-jw tau))`` in output units per input unit.
        """
        omega = np.atleast_1d(np.asarray(omega_rad_s, dtype=float))
        n = self.F.shape[0]
        out = np.empty((len(self.outputs), len(self.inputs), omega.size), dtype=complex)
        delays = np.asarray(self.input_delays_s)
        for k, w in enumerate(omega):
            s = 1j * w
            x = np.linalg.solve(s * np.eye(n) - self.F, self.G)
            out[:, :, k] = (self.H @ x + self.J) * np.exp(-s * delays)[None, :]
        return out


def _xv15(name, description, d, U0, outputs, seed_outputs, delays):
    F = [
        [d["Yv"], d["Yp"], d["Yr"] - U0, G_FT_S2],
        [d["Lv"], d["Lp"], d["Lr"], 0.0],
        [d["Nv"], d["Np"], d["Nr"], 0.0],
        [0.0, 1.0, 0.0, 0.0],
    ]
    G = [
        [d["Yda"], d["Ydr"]],
        [d["Lda"], d["Ldr"]],
        [d["Nda"], d["Ndr"]],
        [0.0, 0.0],
    ]
    gust_F = [
        [-d["Yv"], -d["Yp"]],
        [-d["Lv"], -d["Lp"]],
        [-d["Nv"], -d["Np"]],
        [0.0, 0.0],
    ]
    rows = {
        "p": ([0.0, RAD2DEG, 0.0, 0.0], [0.0, 0.0], [0.0, 0.0], "deg/s"),
        "r": ([0.0, 0.0, RAD2DEG, 0.0], [0.0, 0.0], [0.0, 0.0], "deg/s"),
        "ay": ([d["Yv"], d["Yp"], d["Yr"], 0.0], [d["Yda"], d["Ydr"]], [-d["Yv"], -d["Yp"]], "ft/s^2"),
        "v": ([1.0, 0.0, 0.0, 0.0], [0.0, 0.0], [0.0, 0.0], "ft/s"),
        "phi": ([0.0, 0.0, 0.0, RAD2DEG], [0.0, 0.0], [0.0, 0.0], "deg"),
    }
    if U0 > 0:
        rows["beta"] = ([RAD2DEG / U0, 0.0, 0.0, 0.0], [0.0, 0.0], [-RAD2DEG / U0, 0.0], "deg")
    H = [rows[o][0] for o in outputs]
    J = [rows[o][1] for o in outputs]
    gust_H = [rows[o][2] for o in outputs]
    return LinearVehicleModel(
        name=name,
        description=description,
        states=("v", "p", "r", "phi"),
        state_units=("ft/s", "rad/s", "rad/s", "rad"),
        inputs=("da", "dr"),
        input_units=("deg", "deg"),
        outputs=tuple(outputs),
        output_units=tuple(rows[o][3] for o in outputs),
        F=_frozen(F),
        G=_frozen(G),
        H=_frozen(H),
        J=_frozen(J),
        input_delays_s=tuple(float(t) for t in delays),
        gust_names=("v_g", "p_g"),
        gust_F=_frozen(gust_F),
        gust_H=_frozen(gust_H),
        seed_outputs=tuple(seed_outputs),
        derivatives=dict(d),
        constants={"U0_ft_s": U0, "g_ft_s2": G_FT_S2},
    )


def xv15_cruise() -> LinearVehicleModel:
    """XV-15 lateral-directional model in cruise, 170 kn true airspeed (seed Tables 2.1-2.2).

    Returns
    -------
    LinearVehicleModel
        Outputs ``p, r, ay, beta, phi`` (the seed identified from p, r, ay, beta); delays
        tau_a = 0.0892 s, tau_r = 0.03276 s.
    """
    d = {
        "Yv": -0.2797, "Yp": -1.984, "Yr": 16.44,
        "Lv": -8.119e-3, "Lp": -0.6780, "Lr": 0.0,
        "Nv": 7.240e-3, "Np": -0.2308, "Nr": -0.9759,
        "Yda": 0.0, "Ydr": -0.2173,
        "Lda": -0.07775, "Ldr": -7.024e-3,
        "Nda": -0.02166, "Ndr": 0.02213,
    }
    return _xv15(
        "xv15-cruise",
        "XV-15 tilt-rotor, airplane mode, 170 kn TAS, lateral-directional (seed Tables 2.1-2.2)",
        d,
        U0=170.0 * KNOT_FT_S,
        outputs=("p", "r", "ay", "beta", "phi"),
        seed_outputs=("p", "r", "ay", "beta"),
        delays=(0.08920, 0.03276),
    )


def xv15_hover() -> LinearVehicleModel:
    """XV-15 lateral-directional model in hover, SCAS off (seed Tables 2.3-2.4).

    The bare airframe has an unstable lateral oscillation (about 0.16 +/- 0.44j rad/s), so
    simulated manoeuvres need a stabilising pilot loop (see ``livesweep.sim.scenario``).

    Returns
    -------
    LinearVehicleModel
        Outputs ``p, r, ay, v, phi``; no delays (eliminated in the seed).
    """
    d = {
        "Yv": -0.09755, "Yp": -1.489, "Yr": 0.0,
        "Lv": -4.374e-3, "Lp": -0.2365, "Lr": 0.0,
        "Nv": 7.152e-4, "Np": 0.03862, "Nr": -0.1416,
        "Yda": -0.04523, "Ydr": 0.0,
        "Lda": -0.05777, "Ldr": 0.0,
        "Nda": 5.910e-3, "Ndr": 0.01187,
    }
    return _xv15(
        "xv15-hover",
        "XV-15 tilt-rotor, hover (nacelles 90 deg), SCAS off, lateral-directional (seed Tables 2.3-2.4)",
        d,
        U0=0.0,
        outputs=("p", "r", "ay", "v", "phi"),
        seed_outputs=("p", "r", "ay", "v", "phi"),
        delays=(0.0, 0.0),
    )


MODELS = {"xv15-cruise": xv15_cruise, "xv15-hover": xv15_hover}


def get_model(name: str) -> LinearVehicleModel:
    """Model by registry name; ConfigError naming the value and the known models otherwise."""
    try:
        return MODELS[name]()
    except KeyError:
        raise ConfigError(f"unknown model {name!r}; known models: {', '.join(sorted(MODELS))}") from None
