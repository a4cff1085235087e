"""Report plots: Bode magnitude, phase and coherence per pair, verification time histories and
residual-loop steps.

Each ``*_figure`` function returns a :class:`matplotlib.figure.Figure` built without pyplot, so it
neither needs nor changes the matplotlib backend (inline plots in a notebook keep working; show one
with ``display(fig)`` or save it with ``fig.savefig``). The ``*_plot`` functions write the figure
as a PNG for the report.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from livesweep.spectral.response import FrequencyResponse

__all__ = ["bode_figure", "bode_plot", "time_history_figure", "time_history_plot", "residual_figure",
           "residual_plot"]

ADEQUATE_COHERENCE = 0.6


def bode_plot(response: FrequencyResponse, path, **kwargs) -> Path:
    """Write :func:`bode_figure` of ``response`` as a PNG at ``path``; returns the path."""
    return _save(bode_figure(response, **kwargs), path, dpi=90)


def bode_figure(response: FrequencyResponse, *, title: str = "", units: tuple[str, str] = ("", ""),
                ordinary: FrequencyResponse | None = None, models: list | None = None,
                fit_band_rad_s: tuple | None = None) -> Figure:
    """Magnitude [dB], phase [deg] and coherence against frequency [rad/s], one pair.

    Parameters
    ----------
    response : FrequencyResponse
        The response to plot (conditioned or ordinary).
    title : str
    units : (str, str)
        Output and input units, for the magnitude label.
    ordinary : FrequencyResponse, optional
        The unconditioned estimate of the same pair, drawn thin for comparison.
    models : list of (label, omega, H), optional
        Identified model responses to overlay (dashed).
    fit_band_rad_s : (float, float), optional
        The band the models were fitted over (shaded).

    Returns
    -------
    matplotlib.figure.Figure
    """
    w = response.omega
    eps = np.where(np.isfinite(response.random_error), response.random_error, np.nan)
    mag, ph = response.magnitude_db, response.phase_deg
    coh = np.asarray(response.coherence, float)
    good = np.isfinite(mag) & np.isfinite(ph) & (coh >= ADEQUATE_COHERENCE)
    shown = good if good.any() else np.isfinite(mag) & np.isfinite(ph)
    fig = Figure(figsize=(7.5, 8.0))
    a1, a2, a3 = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.6]})
    label = "conditioned (MISO)" if response.conditioned else "composite"
    # the whole estimate faint, the coherent points (gamma^2 >= 0.6) bold; limits follow those
    a1.semilogx(w, mag, "C0", lw=0.8, alpha=0.35)
    a2.semilogx(w, ph, "C0", lw=0.8, alpha=0.35)
    a1.semilogx(w, np.where(good, mag, np.nan), "C0", lw=1.8, label=f"{label}, γ² ≥ {ADEQUATE_COHERENCE:g}")
    a2.semilogx(w, np.where(good, ph, np.nan), "C0", lw=1.8)
    band_db = np.where(good, 8.69 * eps, np.nan)
    a1.fill_between(w, mag - band_db, mag + band_db, color="C0", alpha=0.15, lw=0, label="±1 random error")
    band_deg = np.where(good, np.rad2deg(eps), np.nan)
    a2.fill_between(w, ph - band_deg, ph + band_deg, color="C0", alpha=0.15, lw=0)
    if ordinary is not None:
        ph_o = np.asarray(ordinary.phase_deg, float)
        both = shown & np.isfinite(ph_o)
        if both.any():      # the same branch as the conditioned estimate: no 360 deg jump between them
            ph_o = ph_o + 360.0 * np.round(np.median(ph[both] - ph_o[both]) / 360.0)
        ok_o = np.asarray(ordinary.coherence, float) >= ADEQUATE_COHERENCE
        a1.semilogx(w, np.where(ok_o, ordinary.magnitude_db, np.nan), "C1", lw=0.8, label="ordinary (SISO)")
        a2.semilogx(w, np.where(ok_o, ph_o, np.nan), "C1", lw=0.8)
    ref_w = w[shown][0] if shown.any() else w[0]
    ref_ph = ph[shown][0] if shown.any() else 0.0
    for k, (label, wm, Hm) in enumerate(models or []):
        a1.semilogx(wm, 20 * np.log10(np.abs(Hm)), ls="--", color=f"C{3 + k}", lw=1.4, label=label)
        ph_m = np.rad2deg(np.unwrap(np.angle(Hm)))
        at = np.interp(np.log(ref_w), np.log(wm), ph_m)
        ph_m += 360.0 * np.round((ref_ph - at) / 360.0)      # same branch as the data
        a2.semilogx(wm, ph_m, ls="--", color=f"C{3 + k}", lw=1.4)
    for a, y, pad in ((a1, mag, 3.0), (a2, ph, 15.0)):
        if shown.any():
            lo, hi = float(np.min(y[shown])), float(np.max(y[shown]))
            a.set_ylim(lo - pad - 0.1 * (hi - lo), hi + pad + 0.1 * (hi - lo))
    if fit_band_rad_s is not None:
        for a in (a1, a2, a3):
            a.axvspan(*fit_band_rad_s, color="0.85", alpha=0.4, lw=0)
    a3.semilogx(w, coh, "C2", lw=1.4, label="partial coherence" if response.conditioned else "coherence")
    a3.axhline(ADEQUATE_COHERENCE, color="k", lw=0.7, ls="--")
    a3.set_ylim(0, 1.05)
    out_u, in_u = units
    a1.set_ylabel(f"|{response.output}/{response.input}| [dB{' ' + out_u + '/' + in_u if out_u else ''}]")
    a2.set_ylabel("phase [deg]")
    a3.set_ylabel("γ²")
    a3.set_xlabel("frequency [rad/s]")
    for a in (a1, a2, a3):
        a.grid(True, which="major", lw=0.4)
        a.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())   # minor log ticks: a third of the drawing time
    a1.legend(fontsize=8, loc="lower left")          # "best" costs a search over every line
    a3.legend(fontsize=8, loc="lower left")
    fig.suptitle(title or f"{response.output} / {response.input}")
    fig.subplots_adjust(left=0.12, right=0.97, top=0.94, bottom=0.07, hspace=0.08)   # tight_layout draws twice
    return fig


def time_history_plot(t_s, measured, predicted, inputs, names, units, input_names, path, **kwargs) -> Path:
    """Write :func:`time_history_figure` as a PNG at ``path``; returns the path."""
    return _save(time_history_figure(t_s, measured, predicted, inputs, names, units, input_names, **kwargs), path,
                 dpi=90)


def time_history_figure(t_s, measured, predicted, inputs, names, units, input_names, *, title: str = "",
                        tic=None) -> Figure:
    """Verification plot: measured (solid) and model (dashed) outputs, and the inputs, against time.

    Parameters
    ----------
    t_s : array, shape (N,)
        Time [s].
    measured, predicted : array, shape (n_outputs, N)
        Flight data and model, in the outputs' units.
    inputs : array, shape (n_inputs, N)
    names, units : sequence of str
        Output names and units.
    input_names : sequence of str
    title : str
    tic : sequence of float, optional
        Theil inequality coefficient per output, printed on its axis.
    """
    n = len(names)
    fig = Figure(figsize=(8.0, 1.7 * (n + 1) + 0.6))
    axes = fig.subplots(n + 1, 1, sharex=True)
    for k, ax in enumerate(axes[:-1]):
        ax.plot(t_s, measured[k], "k", lw=1.0, label="flight")
        ax.plot(t_s, predicted[k], "C3--", lw=1.2, label="model")
        lab = f"{names[k]} [{units[k]}]" if units and units[k] else names[k]
        ax.set_ylabel(lab)
        if tic is not None:
            ax.text(0.99, 0.85, f"TIC {tic[k]:.3f}", transform=ax.transAxes, ha="right", fontsize=8)
        ax.grid(True, lw=0.3)
    axes[0].legend(fontsize=8, loc="upper left")
    for j, u in enumerate(inputs):
        axes[-1].plot(t_s, u, lw=1.0, label=input_names[j])
    axes[-1].set_ylabel("inputs")
    axes[-1].legend(fontsize=8, loc="upper left")
    axes[-1].set_xlabel("time [s]")
    axes[-1].grid(True, lw=0.3)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.12, right=0.98, top=0.93, bottom=0.08, hspace=0.1)
    return fig


def residual_plot(before, after, path, *, title: str = "") -> Path:
    """Write :func:`residual_figure` as a PNG at ``path``; returns the path."""
    return _save(residual_figure(before, after, title=title), path, dpi=80)


def residual_figure(before, after, *, title: str = "") -> Figure:
    """Frequency-domain residual (data minus model) before and after one residual-loop step.

    Parameters
    ----------
    before, after : sequence of PairResidual
        Same pairs, same order (:func:`livesweep.ident.residual.pair_residuals`).
    title : str

    Returns
    -------
    matplotlib.figure.Figure
        One column per pair, magnitude [dB] over phase [deg], the data's +/-2-sigma random
        error shaded.
    """
    n = len(before)
    cols = min(n, 4)
    blocks = -(-n // cols)                       # pairs in rows of four, magnitude over phase
    fig = Figure(figsize=(3.2 * cols + 0.8, 4.4 * blocks + 0.6))
    axes = fig.subplots(2 * blocks, cols, squeeze=False)
    for k in range(n, blocks * cols):
        axes[2 * (k // cols), k % cols].set_visible(False)
        axes[2 * (k // cols) + 1, k % cols].set_visible(False)
    for k, (b, a) in enumerate(zip(before, after)):
        r0, col = 2 * (k // cols), k % cols
        for row, (yb, ya, sig, unit) in enumerate(((b.magnitude_db, a.magnitude_db, b.sigma_db, "dB"),
                                                  (b.phase_deg, a.phase_deg, b.sigma_deg, "deg"))):
            ax = axes[r0 + row, col]
            ax.fill_between(b.omega, -2 * sig, 2 * sig, color="0.85", label="±2σ random error")
            ax.semilogx(b.omega, yb, color="tab:red", lw=1.3, label="before")
            ax.semilogx(a.omega, ya, color="tab:blue", lw=1.3, label="after")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.grid(True, alpha=0.3)
            ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
            ax.set_ylabel(f"{b.output}/{b.input} [{unit}]", fontsize=9)
            if row == 0:
                ax.tick_params(labelbottom=False)
            else:
                ax.set_xlabel("frequency [rad/s]", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="best")
    if title:
        fig.suptitle(title, fontsize=11)
    fig.subplots_adjust(left=0.08, right=0.98, top=1 - 0.45 / fig.get_figheight(), bottom=0.5 / fig.get_figheight(),
                        wspace=0.35, hspace=0.35)
    return fig


def _save(fig: Figure, path, *, dpi: int) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path
