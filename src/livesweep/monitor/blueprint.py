"""Entity paths and the default Rerun blueprint of the live sweep view (pure, no side effects).

Entity layout (every path below is relative to the recording root; Rerun shows it with a leading ``/``)::

    telemetry/inputs/<name>            Scalars, one series per signal, timeline "flight_time"; the
                                       series name carries the unit ("da [deg]")
    telemetry/outputs/<name>           Scalars
    spectra/<out>_<in>/coherence       LineStrips2D + Points2D, points (log10 omega, gamma^2), grey
                                       below the threshold; Coherence:values (exact gamma^2, float64)
                                       and Coherence:kind ("ordinary" or "partial")
    spectra/<out>_<in>/coherence/grid       grid lines and tick labels of that plot
    spectra/<out>_<in>/coherence/threshold  the coherence threshold (the criteria's, 0.6 by default) as a line
    spectra/<out>_<in>/magnitude_db    LineStrips2D, points (log10 omega, |H| [dB]) + a display transform
    spectra/<out>_<in>/magnitude_db/grid   grid lines and labels for that plot
    spectra/<out>_<in>/phase_deg       LineStrips2D, points (log10 omega, phase [deg])
    spectra/<out>_<in>/phase_deg/grid
    spectra/<out>_<in>/waterfall       Tensor (estimate x frequency bin) of gamma^2 in percent
    focus/coherence, focus/magnitude_db, focus/phase_deg
                                       the swept pair of the test point running (or the last one):
                                       the responses its verdict judged, over its judged band, as the
                                       spectra/ plots are drawn
    status/adequacy                    TextDocument (verdict, coherence kind, sweep, markdown table)
    status/adequacy_fraction           Scalars, one series per pair: adequate fraction of the band
    status/sweep_frequency/<input>     Scalars: the input's current sweep frequency [rad/s] (the
                                       injection's own schedule when the autopilot says it)
    status/sweep_frequency/judged_band_low, .../judged_band_high
                                       Scalars: the band the test point running is judged over [rad/s]
    status/time_remaining/<input>      Scalars: sweep time still needed to the band's top [s]
    status/test_points                 TextDocument: the test points (open one first, then the closed ones)
    status/alerts                      TextLog, level WARN
    model/summary                      TextDocument: the last closed test point's model (breaches first,
                                       per pair structure, band, J, parameters and figures with their
                                       Cramer-Rao bounds and flags, limits)
    model/trend                        TextDocument: each pair's values over the test points, the notes
    model/bode/<out>_<in>/magnitude_db, .../phase_deg
                                       display transform of one pair's Bode plot; children data
                                       (Points2D, (log10 omega, value)), model (LineStrips2D), prediction
                                       (dashed LineStrips2D) and grid; model/bode/<out>_<in>/title
    model/bode/legend                  labels (Points2D) naming the colours of data, model and prediction;
                                       children dots and lines: the samples of those colours
    model/trend_plot/<out>_<in>/<quantity>
                                       display transform of one quantity against the test-point number;
                                       children points (Points2D), bounds (LineStrips2D, value ± bound),
                                       line (LineStrips2D joining the values) and grid

The three frequency plots of a pair are drawn in a fixed box of display units
(:func:`plot_box`), so each view's visual bounds are fixed here and the data are mapped into the
box by a transform the view logs whenever the plotted range changes.

Names are escaped with :func:`rerun.escape_entity_path_part`, so a channel called ``roll rate`` or
``a/b`` stays one path part.
"""

from __future__ import annotations

from collections.abc import Sequence

import rerun as rr
import rerun.blueprint as rrb

from livesweep.spectral.criteria import DEFAULT_CRITERIA

__all__ = [
    "TIMELINE", "ADEQUACY_PATH", "ALERTS_PATH", "FRACTION_PATH", "TEST_POINTS_PATH", "SWEEP_FREQUENCY_PATH",
    "TIME_REMAINING_PATH", "FOCUS_PATH", "BAND_EDGE_PATHS", "telemetry_path", "pair_path", "coherence_path",
    "magnitude_path", "phase_path",
    "waterfall_path", "sweep_frequency_path", "time_remaining_path", "pair_label", "check_names", "plot_box",
    "plot_margins", "PLOT_MARGINS", "default_blueprint", "MODEL_PATH", "MODEL_SUMMARY_PATH", "MODEL_TREND_PATH",
    "MODEL_BODE_PATH", "MODEL_TREND_PLOT_PATH", "MODEL_LEGEND_PATH", "model_pair_path", "model_trend_plot_path",
    "model_box", "trend_box", "TREND_COLUMNS", "MODEL_TITLE_Y", "MODEL_LEGEND_Y",
]

TIMELINE = "flight_time"
ADEQUACY_PATH = "status/adequacy"
ALERTS_PATH = "status/alerts"
FRACTION_PATH = "status/adequacy_fraction"
TEST_POINTS_PATH = "status/test_points"
SWEEP_FREQUENCY_PATH = "status/sweep_frequency"
TIME_REMAINING_PATH = "status/time_remaining"
#: The swept pair of the test point running (or the last one), as its verdict judged it.
FOCUS_PATH = "focus"
#: The edges of the band the running test point is judged over, drawn with the sweep frequency.
BAND_EDGE_PATHS = (f"{SWEEP_FREQUENCY_PATH}/judged_band_low", f"{SWEEP_FREQUENCY_PATH}/judged_band_high")

#: The "Model" tab: the last closed test point's model (entity paths under :data:`MODEL_PATH`).
MODEL_PATH = "model"
MODEL_SUMMARY_PATH = f"{MODEL_PATH}/summary"
MODEL_TREND_PATH = f"{MODEL_PATH}/trend"
MODEL_BODE_PATH = f"{MODEL_PATH}/bode"
MODEL_TREND_PLOT_PATH = f"{MODEL_PATH}/trend_plot"
MODEL_LEGEND_PATH = f"{MODEL_BODE_PATH}/legend"

#: Display units around each frequency plot's box for its tick labels, (left, right, top, bottom),
#: for one input column; with n inputs the columns are n times narrower, so the margins (which
#: hold labels of a fixed size on screen) are n times wider in display units (:func:`plot_margins`).
PLOT_MARGINS = (90.0, 45.0, 50.0, 55.0)
_PLOT_WIDTH = 1000.0
#: The frequency plots of a pair, top to bottom, and each box's height for one input column
#: (display units). All three share one view, so their frequency axes line up whatever the
#: window's shape.
_PLOT_ORDER = ("coherence", "magnitude", "phase")
_PLOT_HEIGHT = {"coherence": 150.0, "magnitude": 240.0, "phase": 240.0}
#: Row shares of a pair's column: the frequency plots' view, the coherence waterfall.
_ROW_SHARES = (3.0, 0.55)

_KIND_DIR = {"input": "inputs", "output": "outputs"}


def telemetry_path(kind: str, name: str) -> str:
    """``telemetry/inputs/<name>`` or ``telemetry/outputs/<name>``; kind is "input" or "output"."""
    try:
        folder = _KIND_DIR[kind]
    except KeyError:
        raise ValueError(f"signal kind must be 'input' or 'output', got {kind!r} (signal {name!r})") from None
    return f"telemetry/{folder}/{rr.escape_entity_path_part(str(name))}"


def pair_path(output: str, input: str) -> str:  # noqa: A002 - the method's words
    """``spectra/<out>_<in>``: the folder of one output/input pair."""
    return f"spectra/{rr.escape_entity_path_part(f'{output}_{input}')}"


def coherence_path(output: str, input: str) -> str:  # noqa: A002
    return f"{pair_path(output, input)}/coherence"


def magnitude_path(output: str, input: str) -> str:  # noqa: A002
    return f"{pair_path(output, input)}/magnitude_db"


def phase_path(output: str, input: str) -> str:  # noqa: A002
    return f"{pair_path(output, input)}/phase_deg"


def waterfall_path(output: str, input: str) -> str:  # noqa: A002
    return f"{pair_path(output, input)}/waterfall"


def sweep_frequency_path(input: str) -> str:  # noqa: A002
    """``status/sweep_frequency/<input>``: the input's current sweep frequency [rad/s]."""
    return f"{SWEEP_FREQUENCY_PATH}/{rr.escape_entity_path_part(str(input))}"


def time_remaining_path(input: str) -> str:  # noqa: A002
    """``status/time_remaining/<input>``: sweep time still needed to reach the band's top [s]."""
    return f"{TIME_REMAINING_PATH}/{rr.escape_entity_path_part(str(input))}"


def model_pair_path(output: str, input: str) -> str:  # noqa: A002
    """``model/bode/<out>_<in>``: one pair's Bode plots of the model tab."""
    return f"{MODEL_BODE_PATH}/{rr.escape_entity_path_part(f'{output}_{input}')}"


def model_trend_plot_path(output: str, input: str, quantity: str) -> str:  # noqa: A002
    """``model/trend_plot/<out>_<in>/<quantity>``: one quantity of a pair against the test-point number."""
    return (f"{MODEL_TREND_PLOT_PATH}/{rr.escape_entity_path_part(f'{output}_{input}')}/"
            f"{rr.escape_entity_path_part(str(quantity))}")


#: Height of each Bode box of the model tab, the space above the magnitude box, and where each
#: column's title and the legend sit in it (display units, y down from the box's top).
_BODE_HEIGHT = 220.0
_BODE_HEAD = 135.0
MODEL_TITLE_Y = -112.0
MODEL_LEGEND_Y = -70.0
#: Height of the trend plots' rows together, and how many quantities each pair's row shows.
_TREND_HEIGHT = 300.0
TREND_COLUMNS = 3


def _slots(total: float, n: int, margin: float) -> tuple[float, float]:
    """(slot, box) sizes of ``n`` equal boxes that share ``total`` display units, each with
    ``margin`` units of labels beside it."""
    slot = total / max(1, int(n))
    return slot, max(slot - margin, 1.0)


def model_box(kind: str, column: int, n_columns: int) -> tuple[float, float, float, float]:
    """``(x, y, width, height)`` of a Bode box of the model tab (display units, y down).

    kind is ``"magnitude"`` or ``"phase"`` (stacked in that order); the pairs of the test point
    sit side by side in ``n_columns`` columns that share the view's fixed width.
    """
    if kind not in ("magnitude", "phase"):
        raise ValueError(f"model plot kind must be 'magnitude' or 'phase', got {kind!r}")
    left, right, top, bottom = PLOT_MARGINS
    slot, w = _slots(_PLOT_WIDTH + left + right, n_columns, left + right)
    y = 0.0 if kind == "magnitude" else _BODE_HEIGHT + bottom + top
    return column * slot, y, w, _BODE_HEIGHT


def trend_box(row: int, column: int, n_rows: int) -> tuple[float, float, float, float]:
    """``(x, y, width, height)`` of a trend plot of the model tab (display units, y down): one row
    per pair (``n_rows`` share the view's fixed height), one of :data:`TREND_COLUMNS` quantities
    per column."""
    left, right, top, bottom = PLOT_MARGINS
    slot_x, w = _slots(_PLOT_WIDTH + left + right, TREND_COLUMNS, left + right)
    slot_y, h = _slots(_TREND_HEIGHT + top + bottom, n_rows, top + bottom)
    return column * slot_x, row * slot_y, w, h


def _model_bounds() -> rrb.VisualBounds2D:
    left, right, top, bottom = PLOT_MARGINS
    _, y, _, h = model_box("phase", 0, 1)
    return rrb.VisualBounds2D(x_range=(-left, _PLOT_WIDTH + right), y_range=(-_BODE_HEAD, y + h + bottom))


def _trend_bounds() -> rrb.VisualBounds2D:
    left, right, top, bottom = PLOT_MARGINS
    return rrb.VisualBounds2D(x_range=(-left, _PLOT_WIDTH + right), y_range=(-top, _TREND_HEIGHT + bottom))


def plot_margins(n_inputs: int) -> tuple[float, float, float, float]:
    """(left, right, top, bottom) display units around each frequency plot's box for its labels."""
    n = max(1, int(n_inputs))
    return tuple(m * n for m in PLOT_MARGINS)


def plot_box(kind: str, n_inputs: int) -> tuple[float, float, float, float]:
    """``(x, y, width, height)`` of a frequency plot's box in its pair's view (display units, y down).

    kind is ``"coherence"``, ``"magnitude"`` or ``"phase"`` (stacked in that order, each with
    :func:`plot_margins` around it). The boxes are taller for more inputs (narrower columns), so
    the stack keeps about the aspect of its panel in the default blueprint.
    """
    if kind not in _PLOT_HEIGHT:
        raise ValueError(f"plot kind must be 'coherence', 'magnitude' or 'phase', got {kind!r}")
    n = max(1, int(n_inputs))
    _, _, top, bottom = plot_margins(n)
    y = 0.0
    for k in _PLOT_ORDER:
        if k == kind:
            return 0.0, y, _PLOT_WIDTH, _PLOT_HEIGHT[k] * n
        y += _PLOT_HEIGHT[k] * n + bottom + top
    raise AssertionError(kind)


def _visual_bounds(n_inputs: int) -> rrb.VisualBounds2D:
    left, right, top, bottom = plot_margins(n_inputs)
    _, y, w, h = plot_box(_PLOT_ORDER[-1], n_inputs)
    return rrb.VisualBounds2D(x_range=(-left, w + right), y_range=(-top, y + h + bottom))


def pair_label(output: str, input: str) -> str:  # noqa: A002
    """How a pair is named to the engineer: ``output/input``."""
    return f"{output}/{input}"


def check_names(inputs: Sequence[str], outputs: Sequence[str]) -> None:
    """Raise ValueError for empty, duplicate or colliding names (``a_b`` + ``c`` vs ``a`` + ``b_c``)."""
    for what, names in (("input", inputs), ("output", outputs)):
        seen = set()
        for n in names:
            if not isinstance(n, str) or not n:
                raise ValueError(f"{what} names must be non-empty strings, got {n!r}")
            if n in seen:
                raise ValueError(f"duplicate {what} name {n!r}")
            seen.add(n)
    paths: dict[str, tuple[str, str]] = {}
    for o in outputs:
        for i in inputs:
            p = pair_path(o, i)
            if p in paths:
                raise ValueError(f"pairs {pair_label(*paths[p])} and {pair_label(o, i)} map to the same "
                                 f"entity path {p!r}; rename a channel")
            paths[p] = (o, i)


def _focus_view() -> rrb.Spatial2DView:
    """The swept pair of the test point, as its verdict judged it (one column of plots)."""
    return rrb.Spatial2DView(origin="/" + FOCUS_PATH,
                             contents=["$origin/coherence/**", "$origin/magnitude_db/**", "$origin/phase_deg/**",
                                       "$origin/title/**"],
                             name="Test point: the swept pair as judged (γ², |H| [dB], phase [deg] vs ω [rad/s])",
                             visual_bounds=_visual_bounds(1))


def _pair_views(output: str, input: str, n_inputs: int, min_coherence: float) -> rrb.Vertical:  # noqa: A002
    """Two stacked views for one pair: coherence, |H| [dB] and phase [deg] against log omega in
    one view (aligned frequency axes), and the coherence waterfall."""
    label = pair_label(output, input)
    root = "/" + pair_path(output, input)
    # The origin is the pair folder (not an entity): the display transform logged on each plot
    # entity only takes effect relative to a view origin above it.
    return rrb.Vertical(
        rrb.Spatial2DView(origin=root,
                          contents=["$origin/coherence/**", "$origin/magnitude_db/**", "$origin/phase_deg/**"],
                          name=f"{label}  γ², |H| [dB], phase [deg] vs ω [rad/s]; grey: γ² < {min_coherence:g}",
                          visual_bounds=_visual_bounds(n_inputs)),
        rrb.TensorView(origin="/" + waterfall_path(output, input), name=f"{label}  γ² [%] waterfall",
                       slice_selection=rrb.TensorSliceSelection(width=1, height=0),
                       scalar_mapping=rrb.TensorScalarMapping(colormap="viridis"),
                       view_fit="fill"),
        name=label,
        row_shares=list(_ROW_SHARES),
    )


def _model_tab() -> rrb.Horizontal:
    """The model of the last closed test point: its fit over the data's Bode plots and its trend
    plots beside the numbers and the trend table."""
    plots = rrb.Vertical(
        rrb.Spatial2DView(origin="/" + MODEL_BODE_PATH,
                          name="Model of the last test point over its data (|H| [dB], phase [deg] vs ω [rad/s])",
                          visual_bounds=_model_bounds()),
        rrb.Spatial2DView(origin="/" + MODEL_TREND_PLOT_PATH,
                          name="Trend: value ± Cramér-Rao bound against the test point",
                          visual_bounds=_trend_bounds()),
        row_shares=[1.6, 1.0],
    )
    text = rrb.Vertical(
        rrb.TextDocumentView(origin="/" + MODEL_SUMMARY_PATH, name="Model: parameters, figures, limits"),
        rrb.TextDocumentView(origin="/" + MODEL_TREND_PATH, name="Trend over the flight"),
        row_shares=[1.5, 1.0],
    )
    return rrb.Horizontal(plots, text, column_shares=[1.45, 1.0], name="Model")


def default_blueprint(inputs: Sequence[str], outputs: Sequence[str], *,
                      history_s: float = 30.0, min_coherence: float = DEFAULT_CRITERIA.min_coherence,
                      active_tab: str | None = None) -> rrb.Blueprint:
    """The default layout of the live view. Pure: builds objects, logs nothing.

    Three tabs. **Test point** (what the operator judges from), three columns: the verdict (with how
    far behind the link the view is), the test points and the alerts; the swept pair of the test
    point running or the last one, as its verdict judged it (coherence, Bode magnitude and phase
    over the judged band), the sweep frequency against the band judged, and the adequate
    fraction; the input and output time series (last ``history_s`` seconds of flight time) and the
    sweep time still needed. **Model**: the model of the last closed test point (its fit over the
    data's Bode plots, its parameters and figures with their bounds, its limits) and the trend of
    its values over the flight. **All pairs**: one tab per output, each with one column per input
    holding that pair's sliding-window coherence, Bode magnitude and phase (one view) and its
    coherence waterfall. The time panel starts collapsed (its time bar stays). ``min_coherence``:
    the criteria's coherence threshold, named in the pair views' titles (below it is drawn grey).
    ``active_tab``: the name of the tab shown first (None: the first, "Test point").
    """
    inputs, outputs = list(inputs), list(outputs)
    check_names(inputs, outputs)
    window = rrb.VisibleTimeRange(TIMELINE,
                                  start=rrb.TimeRangeBoundary.cursor_relative(seconds=-float(history_s)),
                                  end=rrb.TimeRangeBoundary.cursor_relative())
    status = rrb.Vertical(
        rrb.TextDocumentView(origin="/" + ADEQUACY_PATH, name="Verdict and status"),
        rrb.TextDocumentView(origin="/" + TEST_POINTS_PATH, name="Test points"),
        rrb.TextLogView(origin="/" + ALERTS_PATH, name="Alerts",
                        columns=rrb.TextLogColumns(text_log_columns=["LogLevel", "Body"])),
        name="Status",
        row_shares=[1.2, 1.3, 0.6],
    )
    focus = rrb.Vertical(
        _focus_view(),
        rrb.TimeSeriesView(origin="/" + SWEEP_FREQUENCY_PATH, name="Sweep frequency and the band judged [rad/s]"),
        rrb.TimeSeriesView(origin="/" + FRACTION_PATH, name="Adequate fraction of band (sliding window)",
                           axis_y=rrb.ScalarAxis(range=(0.0, 1.0))),
        name="Swept axis",
        row_shares=[3.0, 0.9, 0.8],
    )
    series = rrb.Vertical(
        rrb.TimeSeriesView(origin="/telemetry/inputs", name="Inputs", time_ranges=window),
        rrb.TimeSeriesView(origin="/telemetry/outputs", name="Outputs", time_ranges=window),
        rrb.TimeSeriesView(origin="/" + TIME_REMAINING_PATH, name="Sweep time to band top [s]"),
        name="Time series",
        row_shares=[1.0, 1.0, 0.6],
    )
    n_in = max(1, len(inputs))
    tabs = [rrb.Horizontal(*[_pair_views(o, i, n_in, min_coherence) for i in inputs], name=o) for o in outputs]
    pairs = rrb.Tabs(*tabs, name="All pairs (sliding window)") if tabs else rrb.Tabs(name="All pairs (sliding window)")
    main = rrb.Horizontal(status, focus, series, column_shares=[1.0, 1.25, 0.9], name="Test point")
    top = [main, _model_tab(), pairs]
    names = [str(t.name) for t in top]
    if active_tab is not None and active_tab not in names:
        raise ValueError(f"active_tab must be one of {names}, got {active_tab!r}")
    return rrb.Blueprint(
        rrb.Tabs(*top, active_tab=None if active_tab is None else names.index(active_tab)),
        rrb.TimePanel(timeline=TIMELINE, play_state="following", state="collapsed"),
        collapse_panels=True,
        auto_views=False,
    )
