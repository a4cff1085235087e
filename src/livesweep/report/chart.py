"""What the report's plots show, independent of how they are drawn.

A :class:`Chart` is a grid of :class:`Panel` s holding lines, shaded bands, reference lines and
labels in data units. The builders here (:func:`bode_chart`, :func:`time_history_chart`,
:func:`residual_chart`) decide what a Bode, verification or residual plot contains: which points
count as coherent, which phase branch a model is drawn on, which limits the axes take. Two
renderers draw a Chart: :func:`livesweep.report.svg.to_svg` (the report's vector plots, no
matplotlib) and :func:`livesweep.report.plots.to_figure` (a matplotlib Figure for notebooks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.spectral.criteria import DEFAULT_CRITERIA
from livesweep.spectral.response import FrequencyResponse

__all__ = ["Line", "Band", "HLine", "Panel", "Chart", "COLORS", "ADEQUATE_COHERENCE", "bode_chart",
           "time_history_chart", "residual_chart"]

#: coherence from which a point is drawn bold and sets the axis limits: the fitting guideline
ADEQUATE_COHERENCE = DEFAULT_CRITERIA.min_coherence

#: the colour cycle (matplotlib's "tab10"), so both renderers draw the same colours
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
          "#bcbd22", "#17becf")
BLACK, LIGHT_GREY = "#000000", "#d9d9d9"


def color(k: int) -> str:
    """Colour ``k`` of the cycle (wraps)."""
    return COLORS[k % len(COLORS)]


@dataclass(frozen=True)
class Line:
    """A polyline in data units; NaN breaks it. ``width`` in points."""

    x: np.ndarray
    y: np.ndarray
    color: str
    width: float = 1.0
    dashed: bool = False
    alpha: float = 1.0
    label: str | None = None


@dataclass(frozen=True)
class Band:
    """The area between ``lo`` and ``hi`` over ``x``; NaN in either leaves a gap."""

    x: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    color: str
    alpha: float = 1.0
    label: str | None = None


@dataclass(frozen=True)
class HLine:
    """A horizontal reference line across the panel at ``y`` [data units]."""

    y: float
    color: str = BLACK
    width: float = 0.7
    dashed: bool = False


@dataclass(frozen=True)
class Panel:
    """One set of axes.

    Attributes
    ----------
    lines, bands, hlines : tuple
        Drawn bands first, then lines in order, then reference lines.
    x_span : (float, float) or None
        A shaded interval of x [data units] (the fitting band).
    x_span_label : str or None
        The shaded interval's legend entry (None: not in the legend).
    y_limits : (float, float) or None
        None: the range of the finite data, with a 5 % margin.
    y_label, x_label, note : str
        Axis labels; ``note`` is written at the top right inside the axes.
    log_x : bool
        Logarithmic frequency axis.
    legend : str or None
        "lower left" or "upper left", or None for no legend.
    x_tick_labels : bool
        False hides the x tick labels (a panel above another sharing its x axis).
    label_size : float
        Font size of the axis labels [pt].
    y_angle : bool
        The y axis is an angle [deg]: ticks at multiples of 15, 30, 45, 90 ...
    """

    lines: tuple = ()
    bands: tuple = ()
    hlines: tuple = ()
    x_span: tuple | None = None
    x_span_label: str | None = None
    y_limits: tuple | None = None
    y_label: str = ""
    x_label: str = ""
    note: str = ""
    log_x: bool = True
    legend: str | None = None
    x_tick_labels: bool = True
    label_size: float = 10.0
    y_angle: bool = False


@dataclass(frozen=True)
class Chart:
    """A grid of panels and its layout.

    Attributes
    ----------
    rows : tuple of tuple of (Panel or None)
        Panels row by row; None leaves a cell empty.
    title : str
    size_in : (float, float)
        Width and height [in].
    height_ratios : tuple of float or None
        Relative row heights (None: equal).
    margins : (left, right, top, bottom)
        Edges of the panel area as fractions of the width and height (matplotlib's
        ``subplots_adjust`` convention).
    hspace, wspace : float
        Gaps between rows and columns as fractions of the mean panel height and width.
    share_x : bool
        Panels of a column share one x range.
    title_size : float
        [pt]
    """

    rows: tuple
    title: str
    size_in: tuple
    height_ratios: tuple | None = None
    margins: tuple = (0.12, 0.97, 0.94, 0.07)
    hspace: float = 0.08
    wspace: float = 0.2
    share_x: bool = True
    title_size: float = 12.0


def bode_chart(response: FrequencyResponse, *, title: str = "", units: tuple[str, str] = ("", ""),
               ordinary: FrequencyResponse | None = None, models: list | None = None,
               fit_band_rad_s: tuple | None = None, fit_band_label: str | None = None,
               min_coherence: float = ADEQUATE_COHERENCE) -> Chart:
    """Magnitude [dB], phase [deg] and coherence against frequency [rad/s] of one pair.

    Parameters
    ----------
    response : FrequencyResponse
        The response to plot (conditioned or ordinary).
    title : str
    units : (str, str)
        Output and input units, for the magnitude label.
    ordinary : FrequencyResponse, optional
        The unconditioned estimate of the same pair, drawn thin for comparison.
    models : list of (label, omega, H) or (label, omega, H, dashed[, colour]), optional
        Identified model responses to overlay (dashed unless ``dashed`` is False); ``omega``
        [rad/s], ``H`` complex; ``colour``: index into :data:`COLORS` (default: the next after
        the data's), so a model keeps its colour on every plot.
    fit_band_rad_s : (float, float), optional
        The band the models were fitted over (shaded).
    fit_band_label : str, optional
        The shaded band's legend entry (default "fit band").
    min_coherence : float
        The coherence threshold of the criteria that judged the response: points below it are
        drawn faint, and it is the dashed line on the coherence panel.

    Returns
    -------
    Chart
        The whole estimate faint, the points with coherence >= ``min_coherence`` bold with
        +/-1 random error shaded; the axis limits follow the coherent points and the models over
        the coherent frequencies (a model far from the data is cut at the axes, never draws the
        data small); model phase on the data's branch.
    """
    w = np.asarray(response.omega, float)
    eps = np.where(np.isfinite(response.random_error), response.random_error, np.nan)
    mag, ph = np.asarray(response.magnitude_db, float), np.asarray(response.phase_deg, float)
    coh = np.asarray(response.coherence, float)
    good = np.isfinite(mag) & np.isfinite(ph) & (coh >= min_coherence)
    shown = good if good.any() else np.isfinite(mag) & np.isfinite(ph)
    label = "conditioned (MISO)" if response.conditioned else "composite"
    c0 = color(0)
    mag_lines = [Line(w, mag, c0, 0.8, alpha=0.35),
                 Line(w, np.where(good, mag, np.nan), c0, 1.8, label=f"{label}, γ² ≥ {min_coherence:g}")]
    ph_lines = [Line(w, ph, c0, 0.8, alpha=0.35), Line(w, np.where(good, ph, np.nan), c0, 1.8)]
    band_db = np.where(good, 20.0 / np.log(10.0) * eps, np.nan)        # dB of a relative error eps
    band_deg = np.where(good, np.rad2deg(eps), np.nan)
    mag_bands = (Band(w, mag - band_db, mag + band_db, c0, 0.15, "±1 random error"),)
    ph_bands = (Band(w, ph - band_deg, ph + band_deg, c0, 0.15),)
    if ordinary is not None:
        ph_o = np.asarray(ordinary.phase_deg, float)
        both = shown & np.isfinite(ph_o)
        if both.any():      # the same branch as the conditioned estimate: no 360 deg jump between them
            ph_o = ph_o + 360.0 * np.round(np.median(ph[both] - ph_o[both]) / 360.0)
        ok_o = np.asarray(ordinary.coherence, float) >= min_coherence
        mag_lines.append(Line(w, np.where(ok_o, ordinary.magnitude_db, np.nan), color(1), 0.8, label="ordinary (SISO)"))
        ph_lines.append(Line(w, np.where(ok_o, ph_o, np.nan), color(1), 0.8))
    ref_w = w[shown][0] if shown.any() else w[0]
    ref_ph = ph[shown][0] if shown.any() else 0.0
    w_lo, w_hi = (float(w[shown][0]), float(w[shown][-1])) if shown.any() else (float(w[0]), float(w[-1]))
    extent = {"mag": [mag[shown]], "ph": [ph[shown]]}
    for k, (name, wm, Hm, *style) in enumerate(models or []):
        dashed = style[0] if style else True
        c = color(style[1]) if len(style) > 1 else color(3 + k)
        wm, Hm = np.asarray(wm, float), np.asarray(Hm, complex)
        ph_m = np.rad2deg(np.unwrap(np.angle(Hm)))
        at = np.interp(np.log(ref_w), np.log(wm), ph_m)
        ph_m = ph_m + 360.0 * np.round((ref_ph - at) / 360.0)      # same branch as the data
        with np.errstate(divide="ignore"):
            mag_m = 20 * np.log10(np.abs(Hm))
        mag_lines.append(Line(wm, mag_m, c, 1.4, dashed=dashed, label=name))
        ph_lines.append(Line(wm, ph_m, c, 1.4, dashed=dashed))
        inside = (wm >= w_lo) & (wm <= w_hi) & np.isfinite(mag_m) & np.isfinite(ph_m)
        extent["mag"].append(mag_m[inside])
        extent["ph"].append(ph_m[inside])
    limits = []
    for key, y, pad, reach in (("mag", mag, 3.0, 20.0), ("ph", ph, 15.0, 180.0)):
        if shown.any():
            lo, hi = float(np.min(y[shown])), float(np.max(y[shown]))
            every = np.concatenate(extent[key])     # the models, at most ``reach`` beyond the data
            lo, hi = max(min(lo, float(np.min(every))), lo - reach), min(max(hi, float(np.max(every))), hi + reach)
            limits.append((lo - pad - 0.1 * (hi - lo), hi + pad + 0.1 * (hi - lo)))
        else:
            limits.append(None)
    out_u, in_u = units
    span = tuple(float(v) for v in fit_band_rad_s) if fit_band_rad_s is not None else None
    p_mag = Panel(lines=tuple(mag_lines), bands=mag_bands, x_span=span, y_limits=limits[0], legend="lower left",
                  x_span_label=(fit_band_label or "fit band") if span else None,
                  y_label=f"|{response.output}/{response.input}| [dB{' ' + out_u + '/' + in_u if out_u else ''}]",
                  x_tick_labels=False)
    p_ph = Panel(lines=tuple(ph_lines), bands=ph_bands, x_span=span, y_limits=limits[1], y_label="phase [deg]",
                 x_tick_labels=False, y_angle=True)
    p_coh = Panel(lines=(Line(w, coh, color(2), 1.4,
                              label="partial coherence" if response.conditioned else "coherence"),),
                  hlines=(HLine(min_coherence, dashed=True),), x_span=span, y_limits=(0.0, 1.05), y_label="γ²",
                  x_label="frequency [rad/s]", legend="lower left")
    return Chart(rows=((p_mag,), (p_ph,), (p_coh,)), title=title or f"{response.output} / {response.input}",
                 size_in=(7.5, 8.0), height_ratios=(3.0, 3.0, 1.6), margins=(0.12, 0.97, 0.94, 0.07), hspace=0.08)


def time_history_chart(t_s, measured, predicted, inputs, names, units, input_names, *, title: str = "",
                       tic=None) -> Chart:
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
        Theil inequality coefficient per output, written on its panel.

    Returns
    -------
    Chart
        One panel per output and one for the inputs, sharing the time axis.
    """
    t = np.asarray(t_s, float)
    n = len(names)
    rows = []
    for k in range(n):
        lab = f"{names[k]} [{units[k]}]" if units and units[k] else names[k]
        rows.append((Panel(lines=(Line(t, np.asarray(measured[k], float), BLACK, 1.0, label="flight"),
                                  Line(t, np.asarray(predicted[k], float), color(3), 1.2, dashed=True, label="model")),
                           y_label=lab, log_x=False, legend="upper left" if k == 0 else None, x_tick_labels=False,
                           note=f"TIC {tic[k]:.3f}" if tic is not None else ""),))
    rows.append((Panel(lines=tuple(Line(t, np.asarray(u, float), color(j), 1.0, label=input_names[j])
                                   for j, u in enumerate(inputs)),
                       y_label="inputs", x_label="time [s]", log_x=False, legend="upper left"),))
    return Chart(rows=tuple(rows), title=title, size_in=(8.0, 1.7 * (n + 1) + 0.6), margins=(0.12, 0.98, 0.93, 0.08),
                 hspace=0.1)


def residual_chart(before, after, *, title: str = "") -> Chart:
    """Frequency-domain residual (data minus model) before and after one residual-loop step.

    Parameters
    ----------
    before, after : sequence of PairResidual
        Same pairs, same order (:func:`livesweep.ident.residual.pair_residuals`).
    title : str

    Returns
    -------
    Chart
        One column per pair (rows of four), magnitude [dB] over phase [deg], the data's
        +/-2-sigma random error shaded.
    """
    n = len(before)
    cols = max(1, min(n, 4))
    blocks = max(1, -(-n // cols))
    grid: list[list] = [[None] * cols for _ in range(2 * blocks)]
    for k, (b, a) in enumerate(zip(before, after)):
        r0, col = 2 * (k // cols), k % cols
        for row, (yb, ya, sig, unit) in enumerate(((b.magnitude_db, a.magnitude_db, b.sigma_db, "dB"),
                                                  (b.phase_deg, a.phase_deg, b.sigma_deg, "deg"))):
            sig = np.asarray(sig, float)
            grid[r0 + row][col] = Panel(
                lines=(Line(np.asarray(b.omega, float), np.asarray(yb, float), color(3), 1.3, label="before"),
                       Line(np.asarray(a.omega, float), np.asarray(ya, float), color(0), 1.3, label="after")),
                bands=(Band(np.asarray(b.omega, float), -2 * sig, 2 * sig, LIGHT_GREY, 1.0, "±2σ random error"),),
                hlines=(HLine(0.0, width=0.5),), y_label=f"{b.output}/{b.input} [{unit}]", label_size=9.0,
                y_angle=row == 1,
                x_label="frequency [rad/s]" if row == 1 else "", x_tick_labels=row == 1,
                legend="upper left" if k == 0 and row == 0 else None)
    height = 4.4 * blocks + 0.6
    return Chart(rows=tuple(tuple(r) for r in grid), title=title, size_in=(3.2 * cols + 0.8, height),
                 margins=(0.08, 0.98, 1 - 0.45 / height, 0.5 / height), hspace=0.35, wspace=0.35, share_x=False,
                 title_size=11.0)
