"""Kinematic consistency: Euler-angle rates from body rates, and angle-versus-integrated-rate checks.

method.md §3.2-3.4. The measurement-error model is ``y_meas(t) = (1 + lambda) y(t - dt) + b +
noise``; :func:`check_angle_against_rate` estimates the scale factor, the time skew and the rate
bias between a measured attitude angle and the rate that should be its derivative, all together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np
import scipy.fft
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from livesweep.consistency import usable_mask
from livesweep.errors import ConfigError, check_band, require_number

__all__ = ["euler_angle_rates", "KinematicCheck", "check_angle_against_rate", "zero_phase_bandpass"]


def _detrend(x: np.ndarray) -> np.ndarray:
    """``x`` less its least-squares straight line (``scipy.signal.detrend(x, type="linear")``)."""
    t = np.arange(x.size) - (x.size - 1) / 2.0
    tt = float(t @ t)
    return x - x.mean() - (t * (float(t @ x) / tt) if tt > 0 else 0.0)


def zero_phase_bandpass(x, band_rad_s: tuple[float, float], sample_rate_hz: float) -> np.ndarray:
    """A Butterworth order-2 band-pass applied forward and backward, as its squared magnitude.

    Forward-backward filtering (``scipy.signal.sosfiltfilt`` of ``butter(2, band, "bandpass")``)
    has zero phase and the gain ``|H|^2``; for the bilinear-transform Butterworth band-pass
    ``|H|^2 = 1 / (1 + u^4)`` with ``u = (W^2 - W_lo W_hi) / ((W_hi - W_lo) W)`` and
    ``W = 2 f_s tan(omega / (2 f_s))`` (the pre-warped frequency). That gain is applied here to
    the FFT of ``x`` extended at both ends by its odd reflection (as filtfilt pads), long enough
    for the filter's slowest mode to die away, so there is no recursion and no edge start-up.
    Away from the ends it equals sosfiltfilt to within 1e-6 of the signal's range; within a few
    periods of the low band edge of an end it is the cleaner of the two.

    Parameters
    ----------
    x : array, shape (N,)
    band_rad_s : (float, float)
        Pass band [rad/s], ``0 < lo < hi < pi * sample_rate_hz``.
    sample_rate_hz : float

    Returns
    -------
    ndarray, shape (N,)
    """
    x = np.asarray(x, float)
    n = x.size
    if n < 2:
        return np.zeros_like(x)
    lo, hi = band_rad_s
    fs = float(sample_rate_hz)
    pad = min(n - 1, int(math.ceil(4.0 * 2.0 * math.pi / lo * fs)))     # four periods of the low edge
    ext = np.concatenate([2.0 * x[0] - x[pad:0:-1], x, 2.0 * x[-1] - x[-2:-pad - 2:-1]])
    m = scipy.fft.next_fast_len(2 * ext.size, real=True)               # room for the wrap-around
    w = np.linspace(0.0, math.pi, m // 2 + 1)                            # rad/sample of the rfft bins
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        W = 2.0 * fs * np.tan(w / 2.0)
        w_lo, w_hi = 2.0 * fs * np.tan(lo / (2.0 * fs)), 2.0 * fs * np.tan(hi / (2.0 * fs))
        u = (W * W - w_lo * w_hi) / ((w_hi - w_lo) * W)
        gain = 1.0 / (1.0 + u ** 4)
    gain = np.where(np.isfinite(gain), gain, 0.0)
    y = scipy.fft.irfft(scipy.fft.rfft(ext, m) * gain, m)
    return y[pad:pad + n]


def euler_angle_rates(p, q, r, phi, theta) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Euler-angle rates from body angular rates (3-2-1 yaw-pitch-roll sequence).

    ``phi_dot = p + (q sin phi + r cos phi) tan theta``,
    ``theta_dot = q cos phi - r sin phi``,
    ``psi_dot = (q sin phi + r cos phi) / cos theta``.

    Parameters
    ----------
    p, q, r : array_like
        Body roll, pitch and yaw rates [rad/s]. Broadcast together with the angles.
    phi, theta : array_like
        Roll and pitch angles [rad]; ``|theta| < pi/2``.

    Returns
    -------
    phi_dot, theta_dot, psi_dot : ndarray
        Euler-angle rates [rad/s], with the broadcast shape of the inputs.

    Raises
    ------
    ConfigError
        The inputs do not broadcast, or theta reaches +/-90 deg (the 3-2-1 singularity) or beyond,
        which usually means degrees were passed where radians are expected.
    """
    try:
        p, q, r, phi, theta = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (p, q, r, phi, theta)))
    except ValueError as exc:
        raise ConfigError(f"euler_angle_rates: p, q, r, phi, theta do not have compatible shapes ({exc})") from None
    bad = ~(np.abs(theta) < 0.5 * math.pi - 1e-9)
    if np.any(bad & np.isfinite(theta)):
        worst = float(np.max(np.abs(theta[np.isfinite(theta)])))
        raise ConfigError(
            f"euler_angle_rates: theta must be in (-pi/2, pi/2) rad, got |theta| up to {worst:.6g} rad "
            f"({math.degrees(worst):.4g} deg); the 3-2-1 Euler rates are singular at +/-90 deg "
            "(were degrees passed instead of radians?)"
        )
    s, c = np.sin(phi), np.cos(phi)
    qr = q * s + r * c
    phi_dot = p + qr * np.tan(theta)
    theta_dot = q * c - r * s
    psi_dot = qr / np.cos(theta)
    return phi_dot, theta_dot, psi_dot


@dataclass(frozen=True)
class KinematicCheck:
    """Result of :func:`check_angle_against_rate`.

    Attributes
    ----------
    name : str
        E.g. ``"phi vs integral of p"``.
    measured : str
        The measured angle's name.
    reconstructed_from : str
        What the reconstruction was integrated from, e.g. ``"integral of p"``.
    scale_factor_error : float
        lambda [-]: measured angle = (1 + lambda) x reconstruction (so 0.08 = +8 %).
    skew_s : float
        Delta t [s]: measured(t) = (1 + lambda) recon(t - Delta t); > 0 when the measured angle
        lags the reconstruction.
    rate_bias : float
        b [units of the rate signal, e.g. deg/s]: the rate carries an extra constant b, so the
        reconstruction drifts away from the angle by b t.
    rms_residual : float
        RMS of ``angle - (1 + lambda) recon(t - Delta t) - a_j - b' t`` over the fitted samples,
        full band [angle units].
    tolerance_scale : float
        Pass limit on ``|lambda|``.
    tolerance_skew_s : float
        Pass limit on ``|Delta t|`` [s].
    passed : bool
        ``|lambda| <= tolerance_scale`` and ``|Delta t| <= tolerance_skew_s`` (the bias is an
        estimate to remove, not a pass criterion).
    band_rad_s : tuple of float
        Band [rad/s] in which lambda and Delta t were fitted.
    """

    name: str
    measured: str
    reconstructed_from: str
    scale_factor_error: float
    skew_s: float
    rate_bias: float
    rms_residual: float
    tolerance_scale: float
    tolerance_skew_s: float
    passed: bool
    band_rad_s: tuple[float, float]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the runs of True in ``mask``."""
    m = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))


def _finite_number(what: str, value, label: str) -> float:
    return require_number(value, f"angle/rate check {label}: {what}")


def check_angle_against_rate(
    angle: np.ndarray,
    angle_rate: np.ndarray,
    sample_rate_hz: float,
    *,
    valid: np.ndarray | None = None,
    name: str = "",
    band_rad_s: tuple[float, float] = (0.3, 10.0),
    tolerance_scale: float = 0.05,
    tolerance_skew_s: float = 0.02,
    max_skew_s: float = 0.3,
    angle_name: str = "angle",
    rate_name: str = "angle_rate",
) -> KinematicCheck:
    """Scale factor, time skew and rate bias between a measured angle and the integral of its rate.

    Model (docs/method.md §3.3), with ``recon(t) = integral of angle_rate``::

        angle(t) = (1 + lambda) recon(t - dt) + a_j + b' t + noise,    b = -b' / (1 + lambda)

    ``a_j`` is one integration constant per valid stretch j.

    Method (variable projection, time domain):

    1. The rate is integrated on each valid stretch separately (cubic-spline antiderivative,
       exact to fourth order and continuous in t, so ``recon(t - dt)`` is evaluated directly for
       any fractional ``dt`` with no re-interpolation). Samples within ``max_skew_s`` of a
       stretch's ends are left out of the fit so every shift stays inside measured data;
       stretches too short to fit (interior shorter than ``1 / band_lo`` s) are skipped.
    2. Band-limited fit of ``1 + lambda`` and ``dt``: on each stretch both the angle and the
       shifted reconstruction are linearly detrended and band-pass filtered identically
       (:func:`zero_phase_bandpass`: Butterworth order 2 forward and backward, ``band_rad_s``). Detrending removes
       ``a_j + b' t`` exactly (it is the same linear projection on both sides), and the band-pass
       keeps drift, random-walk integration noise and high-frequency noise out of the fit. For a
       given ``dt`` the gain ``1 + lambda`` is the least-squares ratio; ``dt`` minimises the
       remaining squared error: a coarse grid over ``+/- max_skew_s`` (step ``0.25 / band_hi``),
       then bounded Brent refinement to 1e-5 s around the best grid point.
    3. Rate bias: with ``lambda`` and ``dt`` fixed, ``angle - (1 + lambda) recon(t - dt)`` is fitted
       by least squares with one constant per stretch and one common slope ``b'`` (full band,
       docs/method.md §3.3 "Biases"). ``rms_residual`` is the RMS of that fit's residual.

    The time-domain form was chosen over the cross-spectrum form because it needs no window
    choice, uses gaps naturally (each stretch is its own record with its own constant) and gives
    all three parameters from one set of residuals.

    Sign conventions (exact):

    * ``skew_s`` = dt > 0 means the measured angle lags the reconstruction:
      ``angle(t) = (1 + lambda) recon(t - dt)``. If the angle sensor's samples are taken
      ``tau_a`` before their time stamps (``angle_meas(t) = angle(t - tau_a)``) and the rate
      sensor's ``tau_r`` before theirs, then ``dt = tau_a - tau_r``. A rate sensor that samples
      0.04 s before its stamp (rate_meas(t) = rate(t - 0.04)) gives ``skew_s = -0.04``; to align,
      shift the rate 0.04 s earlier (or the angle 0.04 s later).
    * ``scale_factor_error`` = lambda: ``angle = (1 + lambda) recon``. If the angle reads
      ``(1 + e_a)`` x truth and the rate ``(1 + e_r)`` x truth, ``1 + lambda = (1 + e_a)/(1 + e_r)``:
      the check cannot tell which sensor is wrong, only their ratio.
    * ``rate_bias`` = b: ``rate_meas = rate + b`` explains the drift; an angle sensor drifting at
      ``-(1 + lambda) b`` per second looks the same.

    Parameters
    ----------
    angle : ndarray, shape (N,)
        Measured angle (deg or rad), uniformly sampled.
    angle_rate : ndarray, shape (N,)
        The rate that should be its derivative, at the same time stamps, in consistent units
        (deg/s with deg, rad/s with rad). For attitude angles use :func:`euler_angle_rates`.
    sample_rate_hz : float
        Sample rate of both signals [Hz].
    valid : ndarray of bool, shape (N,), optional
        False for samples that must not enter the fit (gaps, dropouts). Non-finite samples of
        either signal are excluded too.
    name : str
        Label of the check; default ``"<angle_name> vs integral of <rate_name>"``.
    band_rad_s : (float, float)
        Fit band [rad/s], ``0 < lo < hi < pi * sample_rate_hz``; use the band where the
        manoeuvre excites the angle.
    tolerance_scale : float
        Pass limit on ``|lambda|`` [-].
    tolerance_skew_s : float
        Pass limit on ``|dt|`` [s].
    max_skew_s : float
        Half-width of the skew search [s]. An estimate at the edge of the search means the true
        skew may be larger.
    angle_name, rate_name : str
        Signal names for the result and for error messages.

    Returns
    -------
    KinematicCheck

    Raises
    ------
    ConfigError
        Shapes differ, a setting is out of range, no valid stretch is long enough to fit, or
        the rate has no content in the band.
    """
    label = name or f"{angle_name} vs integral of {rate_name}"
    angle = np.asarray(angle, dtype=float)
    rate = np.asarray(angle_rate, dtype=float)
    if angle.ndim != 1 or rate.ndim != 1:
        raise ConfigError(
            f"angle/rate check {label}: {angle_name} and {rate_name} must be one-dimensional, "
            f"got shapes {angle.shape} and {rate.shape}"
        )
    if angle.shape != rate.shape:
        raise ConfigError(
            f"angle/rate check {label}: {angle_name} has {angle.size} samples but {rate_name} has {rate.size}"
        )
    fs = _finite_number("sample_rate_hz", sample_rate_hz, label)
    if fs <= 0:
        raise ConfigError(f"angle/rate check {label}: sample_rate_hz must be > 0, got {sample_rate_hz!r}")
    lo, hi = check_band(band_rad_s, f"angle/rate check {label}: band_rad_s", sample_rate_hz=fs)
    tol_scale = _finite_number("tolerance_scale", tolerance_scale, label)
    tol_skew = _finite_number("tolerance_skew_s", tolerance_skew_s, label)
    max_skew = _finite_number("max_skew_s", max_skew_s, label)
    if tol_scale < 0 or tol_skew < 0:
        raise ConfigError(
            f"angle/rate check {label}: tolerances must be >= 0, got tolerance_scale={tolerance_scale!r}, "
            f"tolerance_skew_s={tolerance_skew_s!r}"
        )
    if max_skew <= 0:
        raise ConfigError(f"angle/rate check {label}: max_skew_s must be > 0, got {max_skew_s!r}")

    mask = usable_mask(angle, valid, f"angle/rate check {label}") & np.isfinite(rate)

    bandpass = partial(zero_phase_bandpass, band_rad_s=(lo, hi), sample_rate_hz=fs)
    padlen = 15          # scipy's filtfilt edge for two second-order sections; the shortest stretch stays as it was
    margin = int(math.ceil(max_skew * fs)) + 1
    min_interior = max(padlen + 1, int(math.ceil(fs / lo)), 8)

    stretches = []  # (t_interior, angle_interior, recon_pp, filtered_angle)
    for i0, i1 in _runs(mask):
        if i1 - i0 - 2 * margin < min_interior:
            continue
        t = np.arange(i0, i1) / fs
        recon = CubicSpline(t, rate[i0:i1]).antiderivative()
        sl = slice(i0 + margin, i1 - margin)
        t_in = np.arange(sl.start, sl.stop) / fs
        a_in = angle[sl]
        fa = bandpass(_detrend(a_in))
        stretches.append((t_in, a_in, recon, fa))
    if not stretches:
        raise ConfigError(
            f"angle/rate check {label}: no valid stretch is long enough to fit; each needs "
            f"{(min_interior + 2 * margin) / fs:.3g} s of valid samples of {angle_name} and {rate_name} "
            f"(longest valid run: {max((b - a for a, b in _runs(mask)), default=0) / fs:.3g} s)"
        )

    def sums(dt: float) -> tuple[float, float, float]:
        s_ar = s_rr = s_aa = 0.0
        for t_in, _, recon, fa in stretches:
            fr = bandpass(_detrend(recon(t_in - dt)))
            s_ar += float(fa @ fr)
            s_rr += float(fr @ fr)
            s_aa += float(fa @ fa)
        return s_ar, s_rr, s_aa

    def cost(dt: float) -> float:
        s_ar, s_rr, s_aa = sums(dt)
        return s_aa - s_ar * s_ar / s_rr if s_rr > 0 else s_aa

    _, s_rr0, _ = sums(0.0)
    if not s_rr0 > 0:
        raise ConfigError(
            f"angle/rate check {label}: {rate_name} has no content in the band {lo:g}-{hi:g} rad/s; "
            "nothing to compare"
        )

    step = min(0.25 / hi, max_skew)
    n_grid = int(math.ceil(max_skew / step))
    grid = np.linspace(-max_skew, max_skew, 2 * n_grid + 1)
    costs = np.array([cost(float(d)) for d in grid])
    j = int(np.argmin(costs))
    a_b, b_b = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    opt = minimize_scalar(cost, bounds=(float(a_b), float(b_b)), method="bounded", options={"xatol": 1e-5})
    dt = float(opt.x) if opt.fun <= costs[j] else float(grid[j])
    s_ar, s_rr, _ = sums(dt)
    gain = s_ar / s_rr
    if not gain > 0:
        raise ConfigError(
            f"angle/rate check {label}: {angle_name} and the integral of {rate_name} are anticorrelated "
            f"in the band (gain {gain:.4g}); check the sign convention of the signals"
        )

    # Rate bias: one constant per stretch and one common slope, full band.
    n_tot = sum(s[0].size for s in stretches)
    design = np.zeros((n_tot, len(stretches) + 1))
    resid = np.empty(n_tot)
    row = 0
    for jj, (t_in, a_in, recon, _) in enumerate(stretches):
        n = t_in.size
        design[row:row + n, jj] = 1.0
        design[row:row + n, -1] = t_in
        resid[row:row + n] = a_in - gain * recon(t_in - dt)
        row += n
    t_mean = design[:, -1].mean()
    design[:, -1] -= t_mean  # conditioning; the slope is unchanged
    coef, *_ = np.linalg.lstsq(design, resid, rcond=None)
    slope = float(coef[-1])
    rms = float(np.sqrt(np.mean((resid - design @ coef) ** 2)))

    lam = gain - 1.0
    return KinematicCheck(
        name=label,
        measured=angle_name,
        reconstructed_from=f"integral of {rate_name}",
        scale_factor_error=float(lam),
        skew_s=dt,
        rate_bias=-slope / gain,
        rms_residual=rms,
        tolerance_scale=tol_scale,
        tolerance_skew_s=tol_skew,
        passed=bool(abs(lam) <= tol_scale and abs(dt) <= tol_skew),
        band_rad_s=(lo, hi),
    )
