"""Names of the modes of an identified state-space model, read from its eigenvectors.

A flight-dynamics engineer names a mode by what moves in it: roll rate and bank in the roll
subsidence, sideslip and yaw in the Dutch roll, bank and heading with no sideslip in the spiral,
angle of attack and pitch with no speed change in the short period, speed and pitch attitude at
constant angle of attack in the phugoid. :func:`name_modes` does the same from ``A`` and the state
names; where the eigenvector fits none of the patterns it says what it sees (``"real,
r-dominated"``) or ``"coupled"`` rather than a wrong name.

Two views of each eigenvalue ``lambda`` with right eigenvector ``x`` and left eigenvector ``l``:

**Mode shape** (names the vehicle's modes). The states of the rigid body, each made an
*equivalent angle* [rad] so the components compare across units:

=========================  ===========================  =====================================
state                      scaled as                    reads as
=========================  ===========================  =====================================
``phi theta psi beta       ``|x|``                      the angle
alpha``
``p q r``                  ``|x| / |lambda|``           the angle the rate integrates to
                                                        (``p = lambda phi``; ``r / |lambda|``
                                                        is the heading swing)
``u v w``                  ``|x| / V_c``                ``v / U`` is sideslip, ``w / U``
                                                        angle of attack, ``u / U`` the relative
                                                        speed change
``x y z h``                ``|x| |lambda| / V_c``       the position change over one time
                                                        constant, per the velocity scale
=========================  ===========================  =====================================

with the characteristic velocity ``V_c = max(U, g / |lambda|)``: the airspeed in forward flight;
at hover (``U`` = 0) the velocity gravity builds in one time constant per radian of tilt
(``v' = g phi``), so ``v |lambda| / g`` is the bank angle that drives it. ``U`` is the caller's
``airspeed_m_s`` or, without it, ``|A[v, r]|`` or ``|A[w, q]|`` (the kinematic ``-U r`` and ``+U q``
terms, within the aerodynamic ``Yr``, ``Zq``; 6 % for the XV-15 cruise model); ``g`` is the
caller's ``gravity_m_s2`` or the gravity term of ``A`` (``|A[v, phi]|``, or ``|(A[u, theta],
A[w, theta])|``), else 9.80665. U and g taken from ``A`` are in ``A``'s own velocity units, so a model
in ft/s (the XV-15 cases) needs no conversion.

The states form *motions*: roll (p, phi), yaw (r, psi), sideslip (v, beta), pitch (q, theta),
heave (w, alpha), speed (u), position. A motion's size is the largest of its states (``p /
|lambda|`` and ``phi`` are the same motion; summing would count it twice), and the motion shares
(sum 1) decide the name. ``Mode.participation`` is the per-state scaled shape (sum 1 over the
rigid-body states).

**Participation factors** ``|l_k| |x_k|`` normalised to sum 1 (Perez-Arriaga, Verghese and
Schweppe, IEEE Trans. PAS-101, 1982; ``Mode.participation_factors``): unit-free, so they weigh
states of no common unit. They decide whether a mode is the vehicle's or belongs to dynamics added
to it: states that are not rigid-body states (effect states ``act_``, ``notch_``, ``mode_`` ...
of :mod:`livesweep.effects`, Pade/delay or unknown states). An input actuator is upstream of the
airframe: its right eigenvector drives the rigid body (the airframe's forced response), but its
left eigenvector lives on the actuator state alone, so its participation is 100 % actuator and the
airframe's modes keep 0 % there.

Naming rules (motion shares S; lateral ones renormalised over roll R, yaw Y, sideslip B;
longitudinal ones over pitch P, heave A, speed V; PF = participation factor):

- **added dynamics**: PF of the non-rigid states > :data:`ADDED_SHARE` (0.5) -> named after the
  state of largest PF: ``"actuator at da"``, ``"notch filter at da"``, ``"structural mode at p"``,
  ``"delay approximation at dr"``, else ``"added dynamics (<state>)"``.
- lateral (R + Y + B >= :data:`AXIS_SHARE`, 0.75), oscillatory:
  **Dutch roll** B >= 0.12 and Y >= 0.12, in forward flight (a ``beta`` or ``alpha`` state, or
  ``U |lambda| > g``: airspeed, not gravity, sets the velocity scale; there is no weathercock at
  hover);
  **lateral phugoid** (the hover roll/sway oscillation) B >= 0.2, R >= 0.2, Y < 0.12;
  **roll-spiral oscillation** R >= 0.3, Y >= 0.12, B < 0.12.
- lateral, real:
  **roll subsidence** Y < 0.25 and either R >= 0.6, B < 0.3, or R >= 0.3 at hover, or R >= 0.3 with PF(p) >=
  :data:`PF_SUBSIDENCE` (0.5; at hover the sway ``v`` follows the bank one for one in the scaled
  shape, and the roll-damping equation is what makes the root);
  **spiral** B < 0.15, Y >= 0.2 and a coordinated turn, ``r = (g/U) phi`` within a factor 3
  (``g/U`` from ``A[v, phi] / A[v, r]``, ``A[beta, phi]`` or the caller's U; none at hover, so
  there is no spiral at hover);
  **yaw subsidence** R < 0.2 and either Y >= 0.6, B < 0.3, or Y >= 0.3 with PF(r, psi) >= 0.5.
- longitudinal (P + A + V >= 0.75), oscillatory:
  **short period** A >= 0.15, P >= 0.15, V < 0.15; **phugoid** V >= 0.15, P >= 0.15, A < 0.2.
- longitudinal, real: **heave subsidence** P < 0.15 and either A >= 0.6, V < 0.3, or A >= 0.3
  with PF(w, alpha) >= 0.5; **pitch subsidence** A < 0.15 and either P >= 0.6, V < 0.3, or
  P >= 0.3 with PF(q) >= 0.5; **short period (real)** and **phugoid (real)** by the oscillatory
  rules, and only as two real roots (an overdamped pair).
- a zero eigenvalue (``|lambda| <= 1e-8 max(1, max |lambda|)``): **heading (neutral)** when
  psi-dominated, else ``"neutral, <states>-dominated"``.
- otherwise: **coupled** when lateral and longitudinal shares are both >= 0.25, else
  ``"<kind>, <states>-dominated"`` (states of participation >= :data:`DOMINANT_SHARE`, 0.2, at
  most three, largest first), or **coupled** when no state reaches it.

A name the rules give to more than one mode stays with the best fit (largest sum of the shares its
rule tests); the others get the generic label.

The thresholds were set on the XV-15 cruise and hover models of the seed (Tables 2.1-2.4), the
Boeing 747 longitudinal model of Etkin & Reid, and two models that then changed the rules: the
quadrotor hover model of :mod:`livesweep.sim.models` (its fast real roll and pitch roots brought the
PF(p)/PF(q) alternative and the pair condition on the "(real)" names) and the 747 lateral model
(its roll-heavy Dutch roll, B = Y = 0.19, dropped a B + Y >= 0.35 condition). Only these judged
them without having shaped them: Nelson's Navion (lateral, a sideslip-angle model, and
longitudinal) and the XV-15 derivatives perturbed by up to twice their Cramer-Rao bounds
(tests/test_modes.py).

Guard: the rigid-body names need a rigid-body model. Each attitude present with its rate (phi
and p, theta and q, psi and r) must have its kinematic row: coefficient of the rate in [0.5, 2]
(``phi' = p + r tan theta0``, ``psi' = r / cos theta0``), any other rate below 1.5 and every other
entry below 0.05 in magnitude. A model that fails (random, or phi in deg with p in rad/s and no
``units``) gets the generic labels only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np
import scipy.linalg

from livesweep.effects.table import EFFECT_STATE_PREFIXES

__all__ = ["Mode", "name_modes", "RIGID_STATES", "RIGID_NAMES", "PF_SUBSIDENCE", "ADDED_SHARE", "AXIS_SHARE", "COUPLED_SHARE",
           "DOMINANT_SHARE", "G_DEFAULT_M_S2"]

#: Rigid-body states: name -> (motion, kind).
RIGID_STATES = {
    "p": ("roll", "rate"), "phi": ("roll", "angle"),
    "r": ("yaw", "rate"), "psi": ("yaw", "angle"),
    "v": ("sideslip", "velocity"), "beta": ("sideslip", "angle"),
    "q": ("pitch", "rate"), "theta": ("pitch", "angle"),
    "w": ("heave", "velocity"), "alpha": ("heave", "angle"),
    "u": ("speed", "velocity"),
    "x": ("position_lon", "position"), "z": ("position_lon", "position"), "h": ("position_lon", "position"),
    "y": ("position_lat", "position"),
}
_LATERAL = ("roll", "yaw", "sideslip", "position_lat")
_LONGITUDINAL = ("pitch", "heave", "speed", "position_lon")
_KINEMATIC = (("phi", "p"), ("theta", "q"), ("psi", "r"))

#: A mode whose participation factors are more than this in non-rigid states is named after them.
ADDED_SHARE = 0.5
#: Lateral (or longitudinal) motion share from which the lateral (longitudinal) rules apply.
AXIS_SHARE = 0.75
#: Lateral and longitudinal shares both at least this: "coupled".
COUPLED_SHARE = 0.25
#: A state with at least this participation is named in a generic label.
DOMINANT_SHARE = 0.2
#: g when A has no gravity term and the caller gives none [m/s^2].
G_DEFAULT_M_S2 = 9.80665
_NEUTRAL_REL = 1e-8

# Effect state prefixes (livesweep.effects.table) and other added-dynamics words -> labels.
_EFFECT_LABELS = {"act": "actuator", "actrate": "actuator", "actuator": "actuator", "servo": "actuator",
                  "notch": "notch filter", "notchrate": "notch filter",
                  "mode": "structural mode", "moderate": "structural mode",
                  "pade": "delay approximation", "delay": "delay approximation", "lag": "lag"}
for _p in EFFECT_STATE_PREFIXES:
    _EFFECT_LABELS.setdefault(_p.rstrip("_"), "added dynamics")

_UNIT_FACTORS = {"rad": 1.0, "rad/s": 1.0, "deg": math.pi / 180.0, "deg/s": math.pi / 180.0, "m/s": 1.0,
                 "ft/s": 0.3048, "kn": 0.514444, "kt": 0.514444, "m": 1.0, "ft": 0.3048, "1": 1.0, "": 1.0}

#: Names whose rule needs two modes (the two real roots of an overdamped pair).
_PAIRABLE = {"short period (real)": 2, "phugoid (real)": 2}
#: The rigid-body names (each given to one mode at most, the pairs above to two).
RIGID_NAMES = frozenset({"Dutch roll", "lateral phugoid", "roll-spiral oscillation", "roll subsidence", "spiral",
                         "yaw subsidence", "heave subsidence", "pitch subsidence", "short period", "phugoid",
                         "short period (real)", "phugoid (real)", "heading (neutral)"})
#: A real root whose participation factor in the rate (p, r, q) or in w/alpha is at least this is a
#: subsidence of that motion even when its shape shares the motion (hover: v follows phi).
PF_SUBSIDENCE = 0.5


@dataclass(frozen=True)
class Mode:
    """One mode: a real root or a complex pair (positive imaginary part), and its name.

    Attributes
    ----------
    name : str
        ``"Dutch roll"``, ``"roll subsidence"``, ``"spiral"``, ``"short period"``, ``"phugoid"``,
        ``"lateral phugoid"``, ``"yaw subsidence"``, ... ; ``"actuator at da"``-style names for
        added dynamics; ``"real, r-dominated"``-style or ``"coupled"`` where no name fits.
    kind : str
        ``"oscillatory"`` or ``"real"``.
    eigenvalue : complex
        [rad/s]; a pair is given by its member of positive imaginary part.
    stable : bool
        Real part < 0 (a zero root is not stable).
    omega_n_rad_s, zeta, period_s : float or None
        Natural frequency [rad/s], damping ratio [-] and period ``2 pi / Im`` [s] of a pair.
    time_constant_s, time_to_double_s : float or None
        ``-1/Re`` [s] of a stable real root; ``ln 2 / Re`` [s] of an unstable one.
    participation : mapping of str -> float
        Scaled mode-shape magnitude of each rigid-body state (equivalent angles, module notes), sum
        1; empty when the model has no rigid-body states or none moves. For an added-dynamics mode
        it is the airframe's forced motion, not what named it.
    participation_factors : mapping of str -> float
        ``|l_k x_k|`` of every state, sum 1 (unit-free).
    dominant_states : tuple of str
        States of participation >= :data:`DOMINANT_SHARE`, largest first (for an added-dynamics
        mode or a model with no rigid-body states: of participation factor).
    added_state : str or None
        The added-dynamics state a mode is named after.
    """

    name: str
    kind: str
    eigenvalue: complex
    stable: bool
    omega_n_rad_s: float | None = None
    zeta: float | None = None
    period_s: float | None = None
    time_constant_s: float | None = None
    time_to_double_s: float | None = None
    participation: Mapping[str, float] = field(default_factory=dict, hash=False)
    participation_factors: Mapping[str, float] = field(default_factory=dict, hash=False)
    dominant_states: tuple = ()
    added_state: str | None = None

    def to_dict(self) -> dict:
        """The row of :func:`livesweep.report.summary.modes` (same keys, present in the same cases)
        plus ``name``, ``participation``, ``participation_factors``, ``dominant_states`` and
        ``added_state``."""
        lam = self.eigenvalue
        row = {"kind": self.kind, "eigenvalue": [float(lam.real), float(lam.imag)]}
        if self.kind == "oscillatory":
            row.update(omega_n_rad_s=self.omega_n_rad_s, zeta=self.zeta, period_s=self.period_s)
        row["stable"] = self.stable
        if self.time_constant_s is not None:
            row["time_constant_s"] = self.time_constant_s
        if self.time_to_double_s is not None:
            row["time_to_double_s"] = self.time_to_double_s
        row.update(name=self.name, participation=dict(self.participation),
                   participation_factors=dict(self.participation_factors),
                   dominant_states=list(self.dominant_states), added_state=self.added_state)
        return row


def name_modes(a, states, *, airspeed_m_s=None, gravity_m_s2=None, units=None) -> tuple[Mode, ...]:
    """Name every mode of ``x' = A x`` from its eigenvectors (rules: module notes).

    Parameters
    ----------
    a : array_like, shape (n, n)
        State matrix (``M^-1 F`` of a case; n >= 1), in the states' units.
    states : sequence of str
        State names, as a case's ``[state_space] states``: ``v p r phi`` (lateral), ``u w q theta``
        (longitudinal), ``beta``, ``alpha``, ``psi``, ``x y z h``; any other name (an effect's
        ``act_da``, ``notch_da``, ``x_notch_da_1`` ...) is added dynamics.
    airspeed_m_s : float, optional
        True airspeed U >= 0, in the units of the model's velocity states: m/s when ``units``
        converts them (or they are SI), ft/s for the XV-15 cases as they are. Default: from the kinematic terms of ``A``
        (0 when there are none, i.e. hover).
    gravity_m_s2 : float, optional
        g > 0 in the same velocity units per second. Default: from the gravity terms of ``A``.
    units : mapping of str -> str, optional
        Units of the states (a case's ``[state_space.units]``: ``rad``, ``deg``, ``rad/s``, ``deg/s``,
        ``m/s``, ``ft/s``, ``kn``, ``m``, ``ft``, ``1``): rigid-body states are converted to SI
        (``A -> D A D^-1``) before anything else. States not listed stay as they are.

    Returns
    -------
    tuple of Mode
        One per real root and per complex pair, largest ``|lambda|`` first.

    Raises
    ------
    ValueError
        ``A`` not square, not finite or empty; names not one per state, repeated or not strings; an
        unknown unit or a negative airspeed or gravity.
    """
    A, states = _checked(a, states)
    n = len(states)
    if units:
        A = _to_si(A, states, units)
    airspeed_m_s = _option("airspeed_m_s", airspeed_m_s, zero_ok=True)
    gravity_m_s2 = _option("gravity_m_s2", gravity_m_s2, zero_ok=False)
    idx = {s: i for i, s in enumerate(states)}
    rigid = [s for s in states if s in RIGID_STATES]
    added = [s for s in states if s not in RIGID_STATES] if rigid else []
    U = _airspeed(A, idx, airspeed_m_s)
    g = _gravity(A, idx, U, gravity_m_s2)
    turn = _turn_coefficient(A, idx, U, g, airspeed_m_s)
    rigid_model = bool(rigid) and _kinematics_ok(A, states, idx)

    lam, vl, vr = scipy.linalg.eig(A, left=True, right=True)
    scale = max(1.0, float(np.max(np.abs(lam))))
    found = []
    for k in range(n):
        if lam[k].imag < 0:
            continue
        x, l = vr[:, k], vl[:, k]
        pf = np.abs(l) * np.abs(x)
        pf = pf / pf.sum() if pf.sum() > 0 else np.abs(x) / np.abs(x).sum()
        pfd = {s: float(pf[i]) for i, s in enumerate(states)}
        neutral = abs(lam[k]) <= _NEUTRAL_REL * scale
        kind = "oscillatory" if lam[k].imag > 0 else "real"
        shape = _shape(x, lam[k], rigid, idx, U, g, scale)
        added_share = sum(pfd[s] for s in added)
        if not rigid:
            dom = _dominant(pfd, states)
            name, score, added_state = _generic(kind, neutral, dom), 0.0, None
        elif added_share > ADDED_SHARE:
            added_state = max(added, key=lambda s: pfd[s])
            name, score = _added_name(added_state), 0.0
            dom = _dominant({s: pfd[s] for s in added}, added)
        else:
            added_state = None
            dom = _dominant(shape, rigid)
            forward = "beta" in idx or "alpha" in idx or U * abs(lam[k]) > g
            name, score = (_rigid_name(kind, neutral, shape, pfd, x, idx, lam[k], turn, forward) if rigid_model
                           else (None, 0.0))
            if name is None:
                name = _generic(kind, neutral, dom, _motions(shape))
        found.append(dict(lam=lam[k], kind=kind, neutral=neutral, name=name, score=score, shape=shape, pf=pfd,
                          dom=dom, added_state=added_state))
    _resolve_duplicates(found)
    modes = [_mode(f['lam'], f['kind'], f['name'], f['shape'], f['pf'], f['dom'], f['added_state']) for f in found]
    modes.sort(key=lambda m: -abs(m.eigenvalue))
    return tuple(modes)


# --------------------------------------------------------------------------------------- inputs


def _checked(a, states):
    try:
        A = np.array(a, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"A is not a numeric matrix: {exc}") from None
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise ValueError(f"A must be a non-empty square matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        bad = np.argwhere(~np.isfinite(A))[0]
        raise ValueError(f"A has non-finite entries (first at row {bad[0]}, column {bad[1]}): "
                         "no modes of a model that is not finite")
    states = tuple(states)
    if len(states) != A.shape[0] or not all(isinstance(s, str) and s for s in states):
        raise ValueError(f"states must be {A.shape[0]} non-empty names, one per row of A; got {list(states)}")
    if len(set(states)) != len(states):
        raise ValueError(f"repeated state name(s): {sorted({s for s in states if states.count(s) > 1})}")
    return A, states


def _option(label, val, zero_ok):
    if val is None:
        return None
    try:
        x = float(val)
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and (x >= 0 if zero_ok else x > 0)):
        raise ValueError(f"{label} = {val!r}: must be a finite number {'>= 0' if zero_ok else '> 0'}")
    return x


def _to_si(A, states, units):
    d = np.ones(len(states))
    for i, s in enumerate(states):
        if s in RIGID_STATES and s in units:
            u = str(units[s]).strip()
            if u not in _UNIT_FACTORS:
                raise ValueError(f"units.{s} = {u!r}: unknown (known: {', '.join(k for k in _UNIT_FACTORS if k)})")
            d[i] = _UNIT_FACTORS[u]
    return (A * d[:, None]) / d[None, :]


def _entry(A, idx, row, col):
    if row in idx and col in idx:
        return float(A[idx[row], idx[col]])
    return 0.0


def _airspeed(A, idx, given):
    if given is not None:
        return float(given)
    return max(abs(_entry(A, idx, "v", "r")), abs(_entry(A, idx, "w", "q")))


def _gravity(A, idx, U, given):
    if given is not None:
        return float(given)
    for g in (abs(_entry(A, idx, "v", "phi")), math.hypot(_entry(A, idx, "u", "theta"), _entry(A, idx, "w", "theta")),
              abs(_entry(A, idx, "beta", "phi")) * U, abs(_entry(A, idx, "alpha", "theta")) * U):
        if g > 0:
            return g
    return G_DEFAULT_M_S2


def _turn_coefficient(A, idx, U, g, given_u):
    """g / U [rad/s per rad of bank]: the turn rate of a coordinated turn per bank angle, or None."""
    if given_u is not None:
        return g / given_u if given_u > 0 else None
    vphi, vr = abs(_entry(A, idx, "v", "phi")), abs(_entry(A, idx, "v", "r"))
    if vphi > 0 and vr > 0:
        return vphi / vr
    bphi = abs(_entry(A, idx, "beta", "phi"))
    if bphi > 0:
        return bphi
    return None


def _kinematics_ok(A, states, idx):
    rates = {"p", "q", "r"}
    for angle, rate in _KINEMATIC:
        if angle not in idx or rate not in idx:
            continue
        row = A[idx[angle]]
        if not 0.5 <= row[idx[rate]] <= 2.0:
            return False
        for j, s in enumerate(states):
            if s == rate:
                continue
            if abs(row[j]) > (1.5 if s in rates else 0.05):
                return False
    return True


# --------------------------------------------------------------------------------------- shapes


def _shape(x, lam, rigid, idx, U, g, scale):
    lam_eff = max(abs(lam), _NEUTRAL_REL * scale)
    vc = max(U, g / lam_eff)
    out = {}
    for s in rigid:
        kind = RIGID_STATES[s][1]
        m = abs(x[idx[s]])
        if kind == "rate":
            m /= lam_eff
        elif kind == "velocity":
            m /= vc
        elif kind == "position":
            m *= lam_eff / vc
        out[s] = m
    tot = sum(out.values())
    if not tot > 0 or not math.isfinite(tot):
        return {}
    return {s: float(m / tot) for s, m in out.items()}


def _motions(shape):
    mot = {}
    for s, m in shape.items():
        k = RIGID_STATES[s][0]
        mot[k] = max(mot.get(k, 0.0), m)
    tot = sum(mot.values())
    return {k: m / tot for k, m in mot.items()} if tot > 0 else {}


def _dominant(share, order):
    pos = {s: i for i, s in enumerate(order)}
    dom = sorted((s for s in order if share.get(s, 0.0) >= DOMINANT_SHARE), key=lambda s: (-share[s], pos[s]))
    return tuple(dom[:3])


# --------------------------------------------------------------------------------------- naming


def _generic(kind, neutral, dom, motions=None):
    if motions:
        lat = sum(motions.get(k, 0.0) for k in _LATERAL)
        lon = sum(motions.get(k, 0.0) for k in _LONGITUDINAL)
        if lat >= COUPLED_SHARE and lon >= COUPLED_SHARE:
            return "coupled"
    if not dom:
        return "coupled"
    return f"{'neutral' if neutral else kind}, {'/'.join(dom)}-dominated"


def _added_name(state):
    tokens = state.split("_")
    for i, t in enumerate(tokens):
        label = _EFFECT_LABELS.get(t.lower())
        if label is None:
            continue
        where = tokens[i + 1:]
        while where and where[-1].isdigit():
            where = where[:-1]
        if label == "added dynamics":
            return f"added dynamics ({state})"
        return f"{label} at {'_'.join(where)}" if where else label
    return f"added dynamics ({state})"


def _rigid_name(kind, neutral, shape, pf, x, idx, lam, turn, forward):
    """(name, score) by the rules of the module notes, or (None, 0) when none fits."""
    mot = _motions(shape)
    if not mot:
        return None, 0.0
    if neutral:
        if mot.get("yaw", 0.0) >= 0.6 and "psi" in shape and shape["psi"] >= DOMINANT_SHARE:
            return "heading (neutral)", mot["yaw"]
        return None, 0.0
    lat = sum(mot.get(k, 0.0) for k in _LATERAL)
    lon = sum(mot.get(k, 0.0) for k in _LONGITUDINAL)
    if lat >= AXIS_SHARE:
        R, Y, B = (mot.get(k, 0.0) / lat for k in ("roll", "yaw", "sideslip"))
        pf_p, pf_r = pf.get("p", 0.0), pf.get("r", 0.0) + pf.get("psi", 0.0)
        if kind == "oscillatory":
            if B >= 0.12 and Y >= 0.12 and forward:
                return "Dutch roll", B + Y
            if B >= 0.2 and R >= 0.2 and Y < 0.12:
                return "lateral phugoid", B + R
            if R >= 0.3 and Y >= 0.12 and B < 0.12:
                return "roll-spiral oscillation", R + Y
            return None, 0.0
        # at hover the sway velocity is the translation the bank drives (no sideslip in the
        # aerodynamic sense), so it does not count against a roll subsidence there
        if Y < 0.25 and ((R >= 0.6 and B < 0.3) or (R >= 0.3 and (pf_p >= PF_SUBSIDENCE or not forward))):
            return "roll subsidence", R
        if B < 0.15 and Y >= 0.2 and _coordinated_turn(x, idx, lam, turn):
            return "spiral", R + Y
        if R < 0.2 and ((Y >= 0.6 and B < 0.3) or (Y >= 0.3 and pf_r >= PF_SUBSIDENCE)):
            return "yaw subsidence", Y
        return None, 0.0
    if lon >= AXIS_SHARE:
        P, Al, V = (mot.get(k, 0.0) / lon for k in ("pitch", "heave", "speed"))
        pf_q, pf_w = pf.get("q", 0.0), pf.get("w", 0.0) + pf.get("alpha", 0.0)
        real = "" if kind == "oscillatory" else " (real)"
        if kind == "real":
            if P < 0.15 and ((Al >= 0.6 and V < 0.3) or (Al >= 0.3 and pf_w >= PF_SUBSIDENCE)):
                return "heave subsidence", Al
            if Al < 0.15 and ((P >= 0.6 and V < 0.3) or (P >= 0.3 and pf_q >= PF_SUBSIDENCE)):
                return "pitch subsidence", P
        if Al >= 0.15 and P >= 0.15 and V < 0.15:
            return "short period" + real, Al + P
        if V >= 0.15 and P >= 0.15 and Al < 0.2:
            return "phugoid" + real, V + P
    return None, 0.0


def _coordinated_turn(x, idx, lam, turn):
    """Bank and turn rate of the mode as in a coordinated turn, ``r = (g/U) phi``, within a factor 3."""
    if turn is None or "phi" not in idx:
        return False
    phi = abs(x[idx["phi"]])
    if "r" in idx:
        r = abs(x[idx["r"]])
    elif "psi" in idx:
        r = abs(lam) * abs(x[idx["psi"]])
    else:
        return False
    if phi == 0 or r == 0:
        return False
    k = turn * phi / r
    return 1 / 3 <= k <= 3


def _resolve_duplicates(found):
    """One mode per name; the real roots of an overdamped short period or phugoid come as a pair or not at all."""
    by_name = {}
    for f in found:
        by_name.setdefault(f["name"], []).append(f)
    for name, fs in by_name.items():
        if name not in RIGID_NAMES:
            continue
        keep = _PAIRABLE.get(name, 1)
        fs.sort(key=lambda f: -f["score"])
        drop = fs if name in _PAIRABLE and len(fs) < keep else fs[keep:]
        for f in drop:
            f["name"] = _generic(f["kind"], f["neutral"], f["dom"], _motions(f["shape"]))


def _mode(lam, kind, name, shape, pfd, dom, added_state):
    lam = complex(lam)
    re, im = lam.real, lam.imag
    kw = {}
    if kind == "oscillatory":
        wn = abs(lam)
        kw = dict(omega_n_rad_s=wn, zeta=-re / wn, period_s=2 * math.pi / im)
    elif re < 0:
        kw["time_constant_s"] = -1.0 / re
    elif re > 0:
        kw["time_to_double_s"] = math.log(2.0) / re
    return Mode(name=name, kind=kind, eigenvalue=complex(re, 0.0 if kind == "real" else im), stable=re < 0,
                participation=MappingProxyType(dict(shape)), participation_factors=MappingProxyType(dict(pfd)),
                dominant_states=tuple(dom), added_state=added_state, **kw)

