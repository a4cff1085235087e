"""Handling-qualities and loop quantities from frequency responses (docs/method.md §10).

Every function takes a :class:`~livesweep.spectral.response.FrequencyResponse` or a tuple
``(omega, H)`` (omega [rad/s], H complex). Non-finite points (and, with ``min_coherence``, points of
lower coherence) are dropped; the phase is unwrapped along frequency starting from the principal
value of the lowest frequency, as OFA's tools do. Crossings are located by linear interpolation of
magnitude [dB] and phase [deg] in log10(omega) between the bracketing points. A quantity whose
crossing is not inside the data is ``None`` (not an error).

Definitions (docs/method.md §10, OFA ``BandwidthEst.m``, ``TimeDelayEst.m``, ``GainPhaseMargin.m``):

- ``omega_180``: first frequency where the unwrapped phase of the attitude response falls through -180 deg.
- ``omega_BW,phase``: first frequency where the phase falls through -135 deg.
- ``omega_BW,gain``: frequency where the gain is 6 dB above the gain at omega_180 (the highest
  such downward crossing below omega_180).
- ``omega_BW``: rate-response types the lesser of the two (the one that exists when only one does);
  attitude-command types (ACAH) ``omega_BW,phase``.
- phase delay ``tau_p = -(Phi(2 omega_180) + 180) / (57.3 * 2 omega_180)`` [s]. For a pure
  integrator and delay ``e^(-tau s)/s`` this gives ``tau/2`` (the phase lag beyond -180 deg at
  2 omega_180 divided by 2 omega_180). When the phase between omega_180 and 2 omega_180 is not
  linear, the least-squares variant uses the slope b [deg per rad/s] of a straight line fitted to
  the phase over that band: ``tau_p = -b / (2 * 57.3)`` (identical for a linear phase).
- crossover ``omega_c``: ``|L| = 1`` (0 dB); phase margin ``PM = 180 + angle L(omega_c)`` wrapped to
  (-180, 180]; gain margin ``GM = -20 log10 |L|`` where ``angle L = -180 (mod 360)``. With several
  crossings the one with the smallest |margin| is reported (OFA's ``'min'``).

Sign: the criteria assume the positive-sense response; negate H first for a negative-gain pair
(e.g. the XV-15's p/da with L_da < 0).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from livesweep.errors import ConfigError
from livesweep.spectral.criteria import DEFAULT_CRITERIA
from livesweep.spectral.response import FrequencyResponse

__all__ = ["Bandwidth", "Margins", "omega_180", "bandwidth", "phase_delay", "crossover_and_margins",
           "handling_qualities", "response_kind", "RATE_UNITS", "ATTITUDE_UNITS"]

_R2D = 180.0 / np.pi


class Bandwidth(NamedTuple):
    """Bandwidth figures [rad/s]; None where the defining crossing is not in the data."""

    gain: float | None          # omega_BW,gain
    phase: float | None         # omega_BW,phase
    bandwidth: float | None     # omega_BW
    omega_180: float | None


class Margins(NamedTuple):
    """Loop crossover and stability margins; None where the crossing is not in the data."""

    crossover: float | None         # omega_c [rad/s]
    phase_margin_deg: float | None
    omega_180: float | None         # phase-crossover frequency [rad/s]
    gain_margin_db: float | None


class _Curve(NamedTuple):
    lw: np.ndarray       # log10 omega
    mag: np.ndarray      # dB
    phase: np.ndarray    # deg, unwrapped


def _curve(resp, min_coherence=None, integrate=False) -> _Curve:
    if isinstance(resp, FrequencyResponse):
        w, H = np.asarray(resp.omega, float), np.asarray(resp.H, complex)
        coh = np.asarray(resp.coherence, float)
    else:
        try:
            w, H = resp
        except (TypeError, ValueError):
            raise ConfigError("expected a FrequencyResponse or a tuple (omega, H)") from None
        w, H = np.asarray(w, float).ravel(), np.asarray(H, complex).ravel()
        coh = None
        if w.shape != H.shape:
            raise ConfigError(f"omega and H differ in length ({w.size} vs {H.size})")
    ok = np.isfinite(w) & (w > 0) & np.isfinite(H) & (H != 0)
    if min_coherence is not None:
        if coh is None:
            raise ConfigError("min_coherence needs a FrequencyResponse (an (omega, H) tuple has no coherence)")
        ok &= coh >= float(min_coherence)
    w, H = w[ok], H[ok]
    order = np.argsort(w)
    w, H = w[order], H[order]
    if integrate:
        H = H / (1j * w)
    return _Curve(np.log10(w), 20.0 * np.log10(np.abs(H)),
                  np.rad2deg(np.unwrap(np.angle(H))) if H.size else np.array([]))


def _crossings(y: np.ndarray, level: float, direction: str):
    """Indices i and fractions f of crossings of ``y`` through ``level`` between points i and i+1."""
    if y.size < 2:
        return []
    d = y - level
    a, b = d[:-1], d[1:]
    first = np.arange(a.size) == 0                      # a crossing exactly on a point counts once
    down = ((a > 0) & (b <= 0)) | (first & (a == 0) & (b < 0))
    up = ((a < 0) & (b >= 0)) | (first & (a == 0) & (b > 0))
    sel = down if direction == "down" else up if direction == "up" else (down | up)
    out = []
    for i in np.flatnonzero(sel):
        f = a[i] / (a[i] - b[i]) if a[i] != b[i] else 0.0
        out.append((int(i), float(f)))
    return out


def _at(c: _Curve, i: int, f: float):
    """(omega, mag dB, phase deg) at fraction f between points i and i+1 (linear in log omega)."""
    lw = c.lw[i] + f * (c.lw[i + 1] - c.lw[i])
    return (10.0 ** lw, c.mag[i] + f * (c.mag[i + 1] - c.mag[i]), c.phase[i] + f * (c.phase[i + 1] - c.phase[i]))


def _interp(c: _Curve, omega: float, which: str):
    lw = np.log10(omega)
    if c.lw.size < 2 or lw < c.lw[0] or lw > c.lw[-1]:
        return None
    return float(np.interp(lw, c.lw, c.mag if which == "mag" else c.phase))


def _first_phase_crossing(c: _Curve, level: float):
    x = _crossings(c.phase, level, "down")
    return None if not x else float(_at(c, *x[0])[0])


def omega_180(resp, *, min_coherence=None, integrate: bool = False) -> float | None:
    """Frequency [rad/s] where the unwrapped phase first falls through -180 deg.

    Parameters
    ----------
    resp : FrequencyResponse or (omega, H)
        An attitude response (e.g. phi/delta_lat), or a rate response with ``integrate=True``.
    min_coherence : float, optional
        Drop points with lower coherence (FrequencyResponse only).
    integrate : bool
        Use ``H/(j omega)`` (rate response -> attitude response).

    Returns
    -------
    float or None
    """
    return _first_phase_crossing(_curve(resp, min_coherence, integrate), -180.0)


def bandwidth(resp, kind: str = "rate", *, min_coherence=None, integrate: bool = False) -> Bandwidth:
    """ADS-33-style bandwidth of an attitude response.

    Parameters
    ----------
    resp : FrequencyResponse or (omega, H)
        Attitude response (``integrate=True`` for a rate response such as p/delta_lat).
    kind : {"rate", "attitude"}
        Response type: rate-command (``omega_BW = min(omega_BW,gain, omega_BW,phase)``) or
        attitude-command/attitude-hold (``omega_BW = omega_BW,phase``).
    min_coherence : float, optional
    integrate : bool

    Returns
    -------
    Bandwidth
        ``(gain, phase, bandwidth, omega_180)`` [rad/s]; None where undefined in the data.

    Raises
    ------
    ConfigError
        Unknown ``kind``.
    """
    if kind not in ("rate", "attitude"):
        raise ConfigError(f"bandwidth kind must be 'rate' or 'attitude', got {kind!r}")
    c = _curve(resp, min_coherence, integrate)
    w180 = _first_phase_crossing(c, -180.0)
    w_phase = _first_phase_crossing(c, -135.0)
    w_gain = None
    if w180 is not None:
        level = _interp(c, w180, "mag") + 6.0
        below = [x for x in _crossings(c.mag, level, "down") if _at(c, *x)[0] <= w180]
        if below:
            w_gain = float(_at(c, *below[-1])[0])
    if kind == "attitude":
        w_bw = w_phase
    else:
        have = [v for v in (w_gain, w_phase) if v is not None]
        w_bw = min(have) if have else None
    return Bandwidth(w_gain, w_phase, w_bw, w180)


def phase_delay(resp, method: str = "auto", *, linearity_tol_deg: float = 5.0, min_coherence=None,
                integrate: bool = False) -> float | None:
    """Phase delay tau_p [s] of an attitude response.

    Parameters
    ----------
    resp : FrequencyResponse or (omega, H)
    method : {"auto", "two_point", "lsq"}
        ``"two_point"``: ``tau_p = -(Phi(2 omega_180) + 180) / (57.3 * 2 omega_180)`` (OFA
        ``TimeDelayEst.m``); ``"lsq"``: ``tau_p = -b / (2 * 57.3)`` with b [deg/(rad/s)] the slope
        of a least-squares line through the phase over [omega_180, 2 omega_180]; ``"auto"``: the
        LSQ value when the phase departs from that line by more than ``linearity_tol_deg``, else
        the two-point value.
    linearity_tol_deg : float
        Largest deviation [deg] from the fitted line still called linear.
    min_coherence : float, optional
    integrate : bool
        Use ``H/(j omega)`` (rate response).

    Returns
    -------
    float or None
        None when omega_180 is not in the data or 2 omega_180 lies above it.

    Raises
    ------
    ConfigError
        Unknown ``method``.
    """
    if method not in ("auto", "two_point", "lsq"):
        raise ConfigError(f"phase_delay method must be 'auto', 'two_point' or 'lsq', got {method!r}")
    c = _curve(resp, min_coherence, integrate)
    w180 = _first_phase_crossing(c, -180.0)
    if w180 is None:
        return None
    ph2 = _interp(c, 2.0 * w180, "phase")
    if ph2 is None:
        return None
    two_point = -(ph2 + 180.0) / (_R2D * 2.0 * w180)
    if method == "two_point":
        return float(two_point)
    lw0, lw1 = np.log10(w180), np.log10(2.0 * w180)
    inside = (c.lw > lw0) & (c.lw < lw1)
    om = np.concatenate([[w180], 10.0 ** c.lw[inside], [2.0 * w180]])
    ph = np.concatenate([[-180.0], c.phase[inside], [ph2]])
    b, a = np.polyfit(om, ph, 1)
    lsq = -b / (2.0 * _R2D)
    if method == "lsq":
        return float(lsq)
    nonlinear = np.max(np.abs(ph - (a + b * om))) > float(linearity_tol_deg)
    return float(lsq if nonlinear else two_point)


def crossover_and_margins(L, *, min_coherence=None) -> Margins:
    """Crossover frequency and stability margins of a broken-loop response.

    Parameters
    ----------
    L : FrequencyResponse or (omega, H)
        Broken-loop response (e.g. from :func:`livesweep.spectral.response.broken_loop`).
    min_coherence : float, optional

    Returns
    -------
    Margins
        ``(crossover [rad/s], phase margin [deg], omega_180 [rad/s], gain margin [dB])``; with
        several crossings those with the smallest |margin|; None where no crossing is in the data.
    """
    c = _curve(L, min_coherence)
    wc = pm = None
    for i, f in _crossings(c.mag, 0.0, "any"):
        w, _, ph = _at(c, i, f)
        m = 180.0 - ((-ph) % 360.0)          # 180 + phase, wrapped into (-180, 180]
        if pm is None or abs(m) < abs(pm):
            wc, pm = float(w), float(m)
    w180 = gm = None
    if c.phase.size >= 2:
        k_lo = int(np.floor((c.phase.min() + 180.0) / 360.0))
        k_hi = int(np.ceil((c.phase.max() + 180.0) / 360.0))
        for k in range(k_lo, k_hi + 1):
            for i, f in _crossings(c.phase, -180.0 + 360.0 * k, "any"):
                w, mag, _ = _at(c, i, f)
                g = -mag
                if gm is None or abs(g) < abs(gm):
                    w180, gm = float(w), float(g)
    return Margins(wc, pm, w180, gm)


#: Output units of an angular rate (its attitude response is the rate integrated) and of an attitude.
RATE_UNITS = ("deg/s", "rad/s")
ATTITUDE_UNITS = ("deg", "rad")


def response_kind(output_units: str) -> str | None:
    """``"rate"`` for an angular-rate output, ``"attitude"`` for an angle, None otherwise (the
    handling-qualities criteria are defined on attitude responses only)."""
    u = (output_units or "").strip()
    return "rate" if u in RATE_UNITS else "attitude" if u in ATTITUDE_UNITS else None


def handling_qualities(omega, H, *, coherence=None, output_units: str = "deg/s",
                       min_coherence: float = DEFAULT_CRITERIA.min_coherence) -> dict | None:
    """Bandwidth, phase delay and omega_180 of an attitude response, for the report.

    A rate response (the usual sweep pair, e.g. p/da, output in deg/s or rad/s) is integrated to
    the attitude response the criteria are defined on; an attitude response (output in deg or
    rad) is used as it is; any other output (an acceleration, a sideslip) has no such criteria
    and gives None. A negative control sense (the attitude response starting near +/-180 deg
    at the lowest coherent frequencies, i.e. the rate response near 180 deg) is flipped first.
    Values are None where the crossing is not in the data; with ``coherence``, only points with
    gamma^2 >= ``min_coherence`` (the case's criteria) are read.
    """
    kind = response_kind(output_units)
    if kind is None:
        return None
    H = np.asarray(H, complex)
    w = np.asarray(omega, float)
    coh = np.ones(H.shape) if coherence is None else np.asarray(coherence, float)
    ok = np.isfinite(H) & (coh >= min_coherence)
    if not ok.any():
        ok = np.isfinite(H)
    low = np.flatnonzero(ok)[: max(3, ok.sum() // 10)]
    rate_like = H[low] if kind == "rate" else H[low] * 1j * w[low]      # sign from the rate response at low frequency
    sign = -1.0 if np.median(np.cos(np.angle(rate_like))) < 0 else 1.0
    resp = FrequencyResponse("y", "u", w, sign * H, coh, np.zeros(H.shape))
    integrate = kind == "rate"
    mc = min_coherence if coherence is not None else None
    bw = bandwidth(resp, "rate", integrate=integrate, min_coherence=mc)
    tau_p = phase_delay(resp, integrate=integrate, min_coherence=mc) if bw.omega_180 is not None else None

    def num(x):
        return None if x is None or not np.isfinite(x) else float(x)

    return {"omega_180_rad_s": num(bw.omega_180), "bandwidth_gain_rad_s": num(bw.gain),
            "bandwidth_phase_rad_s": num(bw.phase), "bandwidth_rad_s": num(bw.bandwidth),
            "phase_delay_s": num(tau_p), "sign_flipped": sign < 0,
            "response": "attitude (rate / s)" if integrate else "attitude"}
