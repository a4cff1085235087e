"""Report plots (matplotlib, headless): Bode magnitude, phase and coherence per pair."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from livesweep.spectral.response import FrequencyResponse  # noqa: E402

__all__ = ["bode_plot"]

ADEQUATE_COHERENCE = 0.6


def bode_plot(response: FrequencyResponse, path, *, title: str = "", units: tuple[str, str] = ("", ""),
              ordinary: FrequencyResponse | None = None) -> Path:
    """Write a PNG with magnitude [dB], phase [deg] and coherence against frequency [rad/s].

    Parameters
    ----------
    response : FrequencyResponse
        The response to plot (conditioned or ordinary).
    path : str or Path
        PNG to write.
    title : str
    units : (str, str)
        Output and input units, for the magnitude label.
    ordinary : FrequencyResponse, optional
        The unconditioned estimate of the same pair, drawn thin for comparison.

    Returns
    -------
    Path
    """
    path = Path(path)
    w = response.omega
    eps = np.where(np.isfinite(response.random_error), response.random_error, np.nan)
    mag, ph = response.magnitude_db, response.phase_deg
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(7.5, 8.0), sharex=True,
                                     gridspec_kw={"height_ratios": [3, 3, 1.6]})
    label = "conditioned (MISO)" if response.conditioned else "composite"
    a1.semilogx(w, mag, "C0", lw=1.6, label=label)
    a1.fill_between(w, mag - 8.69 * eps, mag + 8.69 * eps, color="C0", alpha=0.15, lw=0, label="±1 random error")
    a2.semilogx(w, ph, "C0", lw=1.6)
    a2.fill_between(w, ph - np.rad2deg(eps), ph + np.rad2deg(eps), color="C0", alpha=0.15, lw=0)
    if ordinary is not None:
        a1.semilogx(w, ordinary.magnitude_db, "C1", lw=0.8, label="ordinary (SISO)")
        a2.semilogx(w, ordinary.phase_deg, "C1", lw=0.8)
    a3.semilogx(w, response.coherence, "C2", lw=1.4, label="partial coherence" if response.conditioned else "coherence")
    a3.axhline(ADEQUATE_COHERENCE, color="k", lw=0.7, ls="--")
    a3.set_ylim(0, 1.05)
    out_u, in_u = units
    a1.set_ylabel(f"|{response.output}/{response.input}| [dB{' ' + out_u + '/' + in_u if out_u else ''}]")
    a2.set_ylabel("phase [deg]")
    a3.set_ylabel("γ²")
    a3.set_xlabel("frequency [rad/s]")
    for a in (a1, a2, a3):
        a.grid(True, which="both", lw=0.3)
    a1.legend(fontsize=8, loc="best")
    a3.legend(fontsize=8, loc="lower left")
    fig.suptitle(title or f"{response.output} / {response.input}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
