"""Entity paths and the default Rerun blueprint of the live sweep view (pure, no side effects).

Entity layout (every path below is relative to the recording root; Rerun shows it with a leading ``/``)::

    telemetry/inputs/<name>            Scalars, one series per signal, timeline "flight_time"
    telemetry/outputs/<name>           Scalars
    spectra/<out>_<in>/coherence       BarChart: values = gamma^2, abscissa = omega [rad/s]
    spectra/<out>_<in>/magnitude_db    LineStrips2D, points (log10 omega, |H| [dB]) + a static display transform
    spectra/<out>_<in>/magnitude_db/grid   static grid lines and labels for that plot
    spectra/<out>_<in>/phase_deg       LineStrips2D, points (log10 omega, phase [deg])
    spectra/<out>_<in>/phase_deg/grid
    spectra/<out>_<in>/waterfall       Tensor (estimate x frequency bin) of gamma^2 in percent
    status/adequacy                    TextDocument (markdown table)
    status/adequacy_fraction           Scalars, one series per pair: adequate fraction of the band
    status/alerts                      TextLog, level WARN

Names are escaped with :func:`rerun.escape_entity_path_part`, so a channel called ``roll rate`` or
``a/b`` stays one path part.
"""

from __future__ import annotations

from collections.abc import Sequence

import rerun as rr
import rerun.blueprint as rrb

__all__ = [
    "TIMELINE", "ADEQUACY_PATH", "ALERTS_PATH", "FRACTION_PATH",
    "telemetry_path", "pair_path", "coherence_path", "magnitude_path", "phase_path", "waterfall_path",
    "pair_label", "check_names", "default_blueprint",
]

TIMELINE = "flight_time"
ADEQUACY_PATH = "status/adequacy"
ALERTS_PATH = "status/alerts"
FRACTION_PATH = "status/adequacy_fraction"

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


def _pair_views(output: str, input: str) -> rrb.Vertical:  # noqa: A002
    """Four stacked views for one pair: coherence bars, |H| [dB], phase [deg], coherence waterfall."""
    label = pair_label(output, input)
    root = "/" + pair_path(output, input)
    return rrb.Vertical(
        rrb.BarChartView(origin="/" + coherence_path(output, input), name=f"{label}  γ² vs ω [rad/s]"),
        # The origin is the pair folder (not the entity): the display transform logged on
        # magnitude_db / phase_deg only takes effect relative to a view origin above it.
        rrb.Spatial2DView(origin=root, contents=["$origin/magnitude_db/**"],
                          name=f"{label}  |H| [dB] vs log10 ω"),
        rrb.Spatial2DView(origin=root, contents=["$origin/phase_deg/**"],
                          name=f"{label}  phase [deg] vs log10 ω"),
        rrb.TensorView(origin="/" + waterfall_path(output, input), name=f"{label}  γ² [%] waterfall",
                       slice_selection=rrb.TensorSliceSelection(width=1, height=0),
                       scalar_mapping=rrb.TensorScalarMapping(colormap="viridis"),
                       view_fit="fill"),
        name=label,
        row_shares=[1.0, 1.2, 1.2, 1.0],
    )


def default_blueprint(inputs: Sequence[str], outputs: Sequence[str], *,
                      history_s: float = 30.0) -> rrb.Blueprint:
    """The default layout of the live view. Pure: builds objects, logs nothing.

    Left column: input and output time series (last ``history_s`` seconds of flight time), the
    adequacy table, the adequate-fraction history and the alerts. Right: one tab per output, each
    with one column per input holding that pair's coherence bars, Bode magnitude and phase, and
    coherence waterfall.
    """
    inputs, outputs = list(inputs), list(outputs)
    check_names(inputs, outputs)
    window = rrb.VisibleTimeRange(TIMELINE,
                                  start=rrb.TimeRangeBoundary.cursor_relative(seconds=-float(history_s)),
                                  end=rrb.TimeRangeBoundary.cursor_relative())
    left = rrb.Vertical(
        rrb.TimeSeriesView(origin="/telemetry/inputs", name="Inputs", time_ranges=window),
        rrb.TimeSeriesView(origin="/telemetry/outputs", name="Outputs", time_ranges=window),
        rrb.TextDocumentView(origin="/" + ADEQUACY_PATH, name="Excitation adequacy"),
        rrb.TimeSeriesView(origin="/" + FRACTION_PATH, name="Adequate fraction of band",
                           axis_y=rrb.ScalarAxis(range=(0.0, 1.0))),
        rrb.TextLogView(origin="/" + ALERTS_PATH, name="Alerts"),
        name="Telemetry and status",
        row_shares=[1.0, 1.0, 1.4, 0.6, 0.8],
    )
    tabs = [rrb.Horizontal(*[_pair_views(o, i) for i in inputs], name=o) for o in outputs]
    right = rrb.Tabs(*tabs, name="Spectra by output") if tabs else rrb.Tabs(name="Spectra by output")
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[1.0, 2.0]),
        rrb.TimePanel(timeline=TIMELINE, play_state="following"),
        collapse_panels=True,
        auto_views=False,
    )
