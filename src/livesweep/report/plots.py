"""The report's plots as matplotlib Figures, for notebooks and scripts.

Each ``*_figure`` function draws the same :class:`~livesweep.report.chart.Chart` the report
writes as SVG, and returns a :class:`matplotlib.figure.Figure` built without pyplot, so it neither
needs nor changes the matplotlib backend (inline plots in a notebook keep working; show one with
``display(fig)`` or save it with ``fig.savefig("p_da.png")``).
"""

from __future__ import annotations

import matplotlib.ticker
from matplotlib.figure import Figure

from livesweep.report.chart import Chart, bode_chart, residual_chart, time_history_chart

__all__ = ["to_figure", "bode_figure", "time_history_figure", "residual_figure"]


def to_figure(chart: Chart) -> Figure:
    """Draw a :class:`~livesweep.report.chart.Chart` as a matplotlib Figure.

    Parameters
    ----------
    chart : Chart

    Returns
    -------
    matplotlib.figure.Figure
    """
    nrows, ncols = len(chart.rows), max(len(r) for r in chart.rows)
    fig = Figure(figsize=chart.size_in)
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex="col" if chart.share_x else False,
                        gridspec_kw={"height_ratios": list(chart.height_ratios)} if chart.height_ratios else None)
    for r in range(nrows):
        for c in range(ncols):
            p = chart.rows[r][c] if c < len(chart.rows[r]) else None
            ax = axes[r, c]
            if p is None:
                ax.set_visible(False)
                continue
            if p.log_x:
                ax.set_xscale("log")
                ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())   # a third of the drawing time
            if p.x_span is not None:
                ax.axvspan(*p.x_span, color="0.85", alpha=0.4, lw=0, label=p.x_span_label)
            for b in p.bands:
                ax.fill_between(b.x, b.lo, b.hi, color=b.color, alpha=b.alpha, lw=0, label=b.label)
            for s in p.lines:
                ax.plot(s.x, s.y, color=s.color, lw=s.width, ls="--" if s.dashed else "-", alpha=s.alpha,
                        label=s.label)
            for h in p.hlines:
                ax.axhline(h.y, color=h.color, lw=h.width, ls="--" if h.dashed else "-")
            if p.y_limits is not None:
                ax.set_ylim(*p.y_limits)
            if p.y_angle:       # 15, 30, 45, 90 ... degrees
                ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(steps=[1, 1.5, 3, 4.5, 9, 10]))
            ax.set_ylabel(p.y_label, fontsize=p.label_size)
            if p.x_label:
                ax.set_xlabel(p.x_label, fontsize=p.label_size)
            if not p.x_tick_labels:
                ax.tick_params(labelbottom=False)
            if p.note:
                ax.text(0.99, 0.85, p.note, transform=ax.transAxes, ha="right", fontsize=8)
            if p.legend:
                ax.legend(fontsize=8, loc=p.legend)      # a fixed place: "best" searches every line
            ax.grid(True, which="major", lw=0.4)
    if chart.title:
        fig.suptitle(chart.title, fontsize=chart.title_size)
    left, right, top, bottom = chart.margins
    fig.subplots_adjust(left=left, right=right, top=top, bottom=bottom, hspace=chart.hspace, wspace=chart.wspace)
    return fig


def bode_figure(response, **kwargs) -> Figure:
    """:func:`~livesweep.report.chart.bode_chart` as a Figure (same arguments)."""
    return to_figure(bode_chart(response, **kwargs))


def time_history_figure(t_s, measured, predicted, inputs, names, units, input_names, **kwargs) -> Figure:
    """:func:`~livesweep.report.chart.time_history_chart` as a Figure (same arguments)."""
    return to_figure(time_history_chart(t_s, measured, predicted, inputs, names, units, input_names, **kwargs))


def residual_figure(before, after, **kwargs) -> Figure:
    """:func:`~livesweep.report.chart.residual_chart` as a Figure (same arguments)."""
    return to_figure(residual_chart(before, after, **kwargs))
