"""Linear vehicle models for the simulator: the XV-15 lateral-directional models of Tischler & Remple
(Aircraft and Rotorcraft System Identification, AIAA, chapter 2) and a
small quadrotor's roll/pitch attitude dynamics in hover (:func:`quad_attitude`, SI units).

Model structure (both flight conditions, body axes, level trim, small angles, M = I)::

    states  x = [v, p, r, phi]          v in ft/s, p and r in rad/s, phi in rad
    inputs  u = [da, dr]                aileron and rudder in deg (the book's G is per degree)

    v'   = Yv v + Yp p + (Yr - U0) r + g phi + Yda da + Ydr dr
    p'   = Lv v + Lp p + Lr r              + Lda da + Ldr dr
    r'   = Nv v + Np p + Nr r              + Nda da + Ndr dr
    phi' = p

    u(t) enters delayed: u_i(t - tau_i), one delay per input (tau_a, tau_r).

``U0`` (true airspeed, ft/s) enters only through the kinematic ``-U0 r`` term, so ``Yr`` is the
aerodynamic derivative alone (Table 2.1's Yr = 16.44 ft/s/rad; with Yr - U0 the Dutch roll and
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

The derivative values are Tables 2.1-2.4 of that chapter as listed in docs/method.md §11
(English units; eliminated parameters are zero).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.numeric import frozen_array as _frozen

RAD2DEG = 180.0 / np.pi
G_FT_S2 = 32.174
G_M_S2 = 9.80665
KNOT_FT_S = 1.6878099

__all__ = [
    "LinearVehicleModel",
    "xv15_cruise",
    "xv15_hover",
    "quad_attitude",
    "QUAD_AIRFRAME",
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
        The outputs Tischler & Remple identified this model from.
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
    """XV-15 lateral-directional model in cruise, 170 kn true airspeed (Tischler & Remple, Tables 2.1-2.2).

    Returns
    -------
    LinearVehicleModel
        Outputs ``p, r, ay, beta, phi`` (the book identified it from p, r, ay, beta); delays
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
    """XV-15 lateral-directional model in hover, SCAS off (Tischler & Remple, Tables 2.3-2.4).

    The bare airframe has an unstable lateral oscillation (about 0.16 +/- 0.44j rad/s), so
    simulated manoeuvres need a stabilising pilot loop (see ``livesweep.sim.scenario``).

    Returns
    -------
    LinearVehicleModel
        Outputs ``p, r, ay, v, phi``; no delays (eliminated in Tischler & Remple's identification).
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


#: Physical data the quadrotor's derivatives are estimated from (see :func:`quad_attitude`).
QUAD_AIRFRAME = {
    "mass_kg": 1.0,
    "Ixx_kg_m2": 0.010,
    "Iyy_kg_m2": 0.012,
    "arm_m": 0.159,            # motor lever about the roll and pitch axes: 450 mm X frame, 0.225 m / sqrt(2)
    "rotor_radius_m": 0.127,   # 10 in propellers
    "dT_dw_N_s_m": 0.19,       # thrust change per m/s of axial velocity, one rotor in hover
    "dT_cmd_N": 0.63,          # differential thrust per motor at a full (1.0) roll or pitch command
}


def _quad_matrices(d: dict, g: float):
    """F, G and gust_F of the quadrotor model (states v, p, phi, u, q, theta; inputs roll_cmd, pitch_cmd).

    Parameters
    ----------
    d : dict
        Derivatives (SI: 1/s, rad/(m s), rad/s^2 per unit command).
    g : float
        Gravity [m/s^2].

    Returns
    -------
    F, G, gust_F : list of list of float
        ``gust_F`` columns are ``u_g``, ``v_g`` [m/s]: minus the aerodynamic part of the u and v columns.
    """
    F = [
        [d["Yv"], 0.0, g, 0.0, 0.0, 0.0],
        [d["Lv"], d["Lp"], 0.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, d["Xu"], 0.0, -g],
        [0.0, 0.0, 0.0, d["Mu"], d["Mq"], 0.0],
        [0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
    ]
    G = [
        [0.0, 0.0],
        [d["Lroll"], d["Lpitch"]],
        [0.0, 0.0],
        [0.0, 0.0],
        [d["Mroll"], d["Mpitch"]],
        [0.0, 0.0],
    ]
    gust_F = [
        [0.0, -d["Yv"]],
        [0.0, -d["Lv"]],
        [0.0, 0.0],
        [-d["Xu"], 0.0],
        [-d["Mu"], 0.0],
        [0.0, 0.0],
    ]
    return F, G, gust_F


def _quad_outputs(d: dict) -> dict:
    """Output rows of the quadrotor: name -> (H row, J row, gust_H row (u_g, v_g), units)."""
    zero2 = [0.0, 0.0]
    return {
        "p": ([0.0, RAD2DEG, 0.0, 0.0, 0.0, 0.0], zero2, zero2, "deg/s"),
        "q": ([0.0, 0.0, 0.0, 0.0, RAD2DEG, 0.0], zero2, zero2, "deg/s"),
        "phi": ([0.0, 0.0, RAD2DEG, 0.0, 0.0, 0.0], zero2, zero2, "deg"),
        "theta": ([0.0, 0.0, 0.0, 0.0, 0.0, RAD2DEG], zero2, zero2, "deg"),
        "ax": ([0.0, 0.0, 0.0, d["Xu"], 0.0, 0.0], zero2, [-d["Xu"], 0.0], "m/s^2"),
        "ay": ([d["Yv"], 0.0, 0.0, 0.0, 0.0, 0.0], zero2, [0.0, -d["Yv"]], "m/s^2"),
    }


def quad_attitude() -> LinearVehicleModel:
    """A small quadrotor's bare-airframe roll and pitch dynamics in hover (SI units).

    Vehicle: about 1 kg, 450 mm X frame, 10 in propellers (:data:`QUAD_AIRFRAME`), no rate or
    attitude loop in the model (the simulator flies it with one: ``livesweep.sim.scenario``).

    Model (body axes, level hover trim, small angles, M = I; the two axes are uncoupled except
    through the control cross-coupling ``Lpitch``, ``Mroll``)::

        states  x = [v, p, phi, u, q, theta]   v, u in m/s; p, q in rad/s; phi, theta in rad
        inputs  u = [roll_cmd, pitch_cmd]      normalised moment commands, units "1" (-1..1),
                                               as the mixer input (PX4 actuator_controls 0/1)

        v'     = Yv v + g phi                  u'     = Xu u - g theta
        p'     = Lv v + Lp p + Lroll roll_cmd + Lpitch pitch_cmd
        q'     = Mu u + Mq q + Mroll roll_cmd + Mpitch pitch_cmd
        phi'   = p                             theta' = q

    with ``g = 9.80665 m/s^2`` and both inputs delayed by 0.02 s (ESC and motor spin-up latency,
    as a pure delay). Sensed outputs (degrees for angles and rates, as the XV-15 models)::

        p, q       [deg/s]  = 57.2958 p, 57.2958 q
        phi, theta [deg]    = 57.2958 phi, 57.2958 theta
        ax         [m/s^2]  = Xu u     (specific force: u' + g theta)
        ay         [m/s^2]  = Yv v     (specific force: v' - g phi)

    Gusts ``u_g``, ``v_g`` [m/s] enter as the XV-15's ``v_g``: the rotor forces and moments act
    on the air-relative velocities ``u - u_g`` and ``v - v_g``.

    Numbers (representative, not taken from one identified vehicle; estimated from the airframe
    data so that their sizes and signs are physical):

    * ``Lroll = 40``, ``Mpitch = 33`` rad/s^2 per unit: a full command is +/-0.63 N per motor
      (26 % of the 2.45 N hover thrust), 4 x 0.63 N x 0.159 m = 0.40 N m over Ixx = 0.010 and
      Iyy = 0.012 kg m^2.
    * ``Lp = -4.0``, ``Mq = -3.4`` 1/s (rotor damping): the differential-thrust part is
      ``-4 l^2 dT/dw / I = -1.9`` 1/s about roll, with ``dT/dw = 0.19 N/(m/s)`` per rotor from the
      hover heave-damping formula ``dT/dw = 2 a s rho A (Omega R) lambda0 / (16 lambda0 + a s)``
      (Padfield, *Helicopter Flight Dynamics*, 2nd ed., 2007, Ch. 4; a = 5.7, s = 0.10,
      Omega R = 66 m/s, lambda0 = 0.067); the rotors' hub moments under body rate (blade
      flapping lag) add about as much again.
    * ``Yv = -0.30``, ``Xu = -0.25`` 1/s: the rotor drag (induced drag and H-force) linear in the
      air-relative velocity, the "rotor drag" term of Mahony, Kumar and Corke, "Multirotor Aerial
      Vehicles", IEEE Robotics & Automation Magazine 19(3), 2012; 0.25-0.3 N per m/s for a 1 kg
      vehicle.
    * ``Lv = -0.80``, ``Mu = +0.65`` rad/(m s): speed stability from blade flapping (the rotors
      flap away from the relative wind and tilt the thrust back), the signs of a helicopter's
      hover derivatives; 0.008 N m per m/s.
    * ``Lpitch = 4.0``, ``Mroll = -3.3`` rad/s^2 per unit: the autopilot (IMU) sits yawed 0.1 rad
      (5.7 deg) against the frame's mixer axes, so each 0.40 N m command moment has a 10 % component
      about the other body axis (0.04 N m over Ixx, -0.04 N m over Iyy); large enough to identify
      from the off-axis responses.

    The structure (quasi-steady speed derivatives, attitude-rate damping and a delay on the
    control) is the hover bare-airframe structure that frequency-domain identification of small
    quadrotors uses (e.g. Wei, Tischler, Schwartz and Cohen, "System Identification and Controller
    Optimization of a Quadrotor UAV", AHS 71st Forum, 2015).

    Stability: each axis has the characteristic polynomial
    ``s^3 - (Yv + Lp) s^2 + Yv Lp s - g Lv`` (roll) and ``s^3 - (Xu + Mq) s^2 + Xu Mq s + g Mu``
    (pitch). With these numbers both are unstable: a stable real pole at -4.43 (roll) and
    -3.86 rad/s (pitch) and an unstable oscillation at 0.065 +/- 1.329j (roll, time to double
    11 s) and 0.104 +/- 1.281j rad/s (pitch, 7 s), the hover "phugoid" of speed stability and
    gravity. Sweeps therefore need the stabilising loop of ``livesweep.sim.scenario``.

    Returns
    -------
    LinearVehicleModel
        Outputs ``p, q, phi, theta, ax, ay``; gusts ``u_g, v_g`` [m/s]; delays 0.02 s on both inputs.
    """
    d = {
        "Yv": -0.30, "Lv": -0.80, "Lp": -4.0,
        "Xu": -0.25, "Mu": 0.65, "Mq": -3.4,
        "Lroll": 40.0, "Lpitch": 4.0,
        "Mroll": -3.3, "Mpitch": 33.0,
    }
    F, G, gust_F = _quad_matrices(d, G_M_S2)
    rows = _quad_outputs(d)
    outputs = ("p", "q", "phi", "theta", "ax", "ay")
    return LinearVehicleModel(
        name="quad-attitude",
        description="quadrotor, 1 kg, 450 mm X frame, hover, bare airframe roll and pitch (representative)",
        states=("v", "p", "phi", "u", "q", "theta"),
        state_units=("m/s", "rad/s", "rad", "m/s", "rad/s", "rad"),
        inputs=("roll_cmd", "pitch_cmd"),
        input_units=("1", "1"),
        outputs=outputs,
        output_units=tuple(rows[o][3] for o in outputs),
        F=_frozen(F),
        G=_frozen(G),
        H=_frozen([rows[o][0] for o in outputs]),
        J=_frozen([rows[o][1] for o in outputs]),
        input_delays_s=(0.02, 0.02),
        gust_names=("u_g", "v_g"),
        gust_F=_frozen(gust_F),
        gust_H=_frozen([rows[o][2] for o in outputs]),
        seed_outputs=outputs,
        derivatives=dict(d),
        constants={"g_m_s2": G_M_S2, **QUAD_AIRFRAME},
    )


MODELS = {"xv15-cruise": xv15_cruise, "xv15-hover": xv15_hover, "quad-attitude": quad_attitude}


def get_model(name: str) -> LinearVehicleModel:
    """Model by registry name; ConfigError naming the value and the known models otherwise."""
    try:
        return MODELS[name]()
    except KeyError:
        raise ConfigError(f"unknown model {name!r}; known models: {', '.join(sorted(MODELS))}") from None
