"""Drawing the frequency plots and coherence waterfalls of the Rerun view.

Per pair (entity paths: :mod:`.blueprint`), all three plots against ``log10 omega`` with ticks at
the 1-2-5 values labelled in rad/s: coherence gamma^2 (line and points, 0..1, the criteria's threshold, 0.6 by default, as
an orange line), |H| [dB] and phase [deg]. Rerun has no log axis, so each is a
``rr.LineStrips2D`` whose points are ``(log10 omega, value)`` in a Spatial2DView with fixed visual
bounds; a ``rr.Transform3D`` on the entity maps the plotted range onto the view's box (y up) and
is logged again, at the estimate's time, whenever that range changes; the grid and its labels are
a child entity, so they get the same transform.

*Masking*: where gamma^2 is below the threshold the curves are drawn **grey and thin** on all three plots (and the
coherence points grey); a masked magnitude or phase point outside the plotted range is not drawn.
The plotted range follows the coherent points (:func:`.freq_plot.value_extent`: it grows at once
and shrinks when it is more than 1.6 times what the data need).

*Phase*: unwrapped along frequency and moved by whole turns so its value at the lowest coherent
frequency lies in (-180, 180] deg.

The coherence entity also carries ``Coherence:values`` (the exact gamma^2, float64) and
``Coherence:kind`` (``"ordinary"`` or ``"partial"``, also written above the plot's axis).

*Waterfall*: ``rr.Tensor`` of shape (estimates, frequency bins) holding gamma^2 in **percent as
uint8** (value range 0..100), the last ``waterfall_rows`` estimates with the newest in the last
row. The bins are the estimator's log-spaced grid, so its x axis is logarithmic too.

Curves, points and waterfalls are logged as ready Arrow arrays (:mod:`.rerun_compat` builds them)
with their component descriptors: ``rr.log`` with archetype objects costs ~0.3-1.4 ms per spectral
entity. Grids and transforms are logged only when they change.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pyarrow as pa
import rerun as rr

from livesweep.monitor.blueprint import pair_path, plot_box, plot_margins, waterfall_path
from livesweep.monitor.freq_plot import (
    MAG_STEPS_DB, PHASE_STEPS_DEG, frequency_extent, log_ticks, masked_runs, reference_phase, tick_label,
    value_extent,
)

__all__ = ["ArrowBatch", "FrequencyPlots", "PairState", "descriptors"]

_MAG_COLOR = (66, 146, 230)
_PHASE_COLOR = (236, 88, 80)
_COH_COLOR = (60, 190, 90)
_MASKED_COLOR = (125, 125, 125, 200)
_THRESHOLD_COLOR = (255, 165, 0)
_GRID_COLOR = (150, 150, 150, 120)
_GRID_MINOR_COLOR = (150, 150, 150, 45)
#: Line radii [ui points; Rerun encodes ui points as negative radii] of coherent and masked stretches.
_CURVE_RADIUS = -1.5
_MASKED_RADIUS = -0.6


class ArrowBatch:
    """A ``rerun.ComponentBatchLike`` around a ready pyarrow array (logged with a descriptor in
    ``rr.DescribedComponentBatch`` or ``rr.ComponentColumn``)."""

    __slots__ = ("_a",)

    def __init__(self, a: pa.Array) -> None:
        self._a = a

    def as_arrow_array(self) -> pa.Array:
        """The wrapped array."""
        return self._a


def descriptors(archetype) -> dict:
    """Component name (``"Points2D:colors"``) -> ``rr.ComponentDescriptor`` of an archetype instance."""
    return {b.component_descriptor().component: b.component_descriptor()
            for b in archetype.as_component_batches()}


def _rgba(c) -> int:
    """An (r, g, b[, a]) colour, 0-255 each, as Rerun's packed 0xRRGGBBAA."""
    r, g, b = c[:3]
    a = c[3] if len(c) > 3 else 255
    return (int(r) << 24) | (int(g) << 16) | (int(b) << 8) | int(a)


class _Plot:
    """One frequency plot of one pair (coherence, magnitude or phase): its path and what is on screen."""

    __slots__ = ("path", "kind", "unit", "steps", "color", "box", "extent", "grid_key", "margins")

    def __init__(self, path: str, kind: str, unit: str, steps: Sequence[float], color: tuple, box: tuple,
                 margins: tuple) -> None:
        self.path, self.kind, self.unit, self.steps, self.color, self.box = path, kind, unit, steps, color, box
        self.margins = margins                # (left, right, top, bottom) display units for the labels
        self.extent: tuple | None = None     # (y0, y1, step) plotted
        # box = (x, y, width, height) in the pair view's display units (blueprint.plot_box)
        self.grid_key: tuple | None = None   # what the logged transform and grid were made for


class PairState:
    """What the view remembers about one pair's plots under ``root`` (``spectra/<out>_<in>``, or
    ``focus``), drawn in a view of ``n_columns`` columns of plots."""

    __slots__ = ("coh", "mag", "phase", "wf_path", "waterfall", "wf_count")

    def __init__(self, root: str, n_columns: int, wf_path: str | None = None) -> None:
        m = plot_margins(n_columns)
        self.coh = _Plot(f"{root}/coherence", "coherence", "γ²", (0.2,), _COH_COLOR, plot_box("coherence", n_columns), m)
        self.mag = _Plot(f"{root}/magnitude_db", "magnitude", "dB", MAG_STEPS_DB, _MAG_COLOR,
                         plot_box("magnitude", n_columns), m)
        self.phase = _Plot(f"{root}/phase_deg", "phase", "deg", PHASE_STEPS_DEG, _PHASE_COLOR,
                           plot_box("phase", n_columns), m)
        self.coh.extent = (0.0, 1.0, 0.2)
        self.wf_path = wf_path
        self.waterfall: np.ndarray | None = None   # (k, n_f) uint8, never mutated once logged
        self.wf_count = 0


class FrequencyPlots:
    """Every pair's frequency plots and coherence waterfall, drawn into one recording stream.

    Parameters
    ----------
    rec : rerun.RecordingStream
        Where to log; the caller sets the time before each draw.
    n_columns : int
        Plot columns of the "All pairs" view (the number of inputs).
    waterfall_rows : int
        Estimates kept in each coherence waterfall (0: no waterfall).
    waterfall_every : int
        Re-log the waterfalls every k-th estimate (rows are still added on every estimate).
    arrays : livesweep.monitor.rerun_compat.InternalArrays or PublicArrays
        Builds the Arrow arrays of tensors, strips and points (:func:`.rerun_compat.arrays`).
    """

    def __init__(self, rec, n_columns: int, waterfall_rows: int, waterfall_every: int, arrays, *,
                 min_coherence: float) -> None:
        self.rec, self.n_columns, self.arrays = rec, int(n_columns), arrays
        self.min_coherence = float(min_coherence)          # the criteria's: grey below it, its line drawn
        self.waterfall_rows, self.waterfall_every = int(waterfall_rows), int(waterfall_every)
        self.pairs: dict[tuple[str, str], PairState] = {}
        self._grid_cache: tuple[bytes, dict] | None = None
        # Component descriptors of the arrays logged directly (building these archetypes also
        # pays Rerun's one-off lazy initialisation, ~100 ms, here instead of in the first estimate).
        d = descriptors(rr.LineStrips2D([[[0.0, 0.0], [1.0, 1.0]]], colors=[[1, 2, 3]], radii=[1.0]))
        self._d_strips, self._d_strip_colors, self._d_strip_radii = (
            d["LineStrips2D:strips"], d["LineStrips2D:colors"], d["LineStrips2D:radii"])
        d = descriptors(rr.Points2D([[0.0, 0.0]], colors=[[1, 2, 3]]))
        self._d_points, self._d_point_colors = d["Points2D:positions"], d["Points2D:colors"]
        d = descriptors(rr.DynamicArchetype("Coherence", components={"values": np.zeros(1), "kind": "ordinary"}))
        self._d_coh_values, self._d_coh_kind = d["Coherence:values"], d["Coherence:kind"]
        self._d_tensor = descriptors(rr.Tensor(np.zeros((1, 1), np.uint8)))["Tensor:data"]

    def pair(self, o: str, i: str) -> PairState:
        """The plots of pair output ``o`` / input ``i`` (their static properties logged on first use)."""
        st = self.pairs.get((o, i))
        if st is None:
            st = self.pairs[(o, i)] = self.new_pair(pair_path(o, i), self.n_columns, waterfall_path(o, i))
        return st

    def new_pair(self, root: str, n_columns: int, wf_path: str | None) -> PairState:
        """Plots under ``root`` in a view of ``n_columns`` columns, with a waterfall at ``wf_path``
        (None, or no ``waterfall_rows``: without); their static properties are logged now."""
        st = PairState(root, n_columns, wf_path if self.waterfall_rows else None)
        for p in (st.coh, st.mag, st.phase):
            self.rec.log(p.path, rr.LineStrips2D.from_fields(draw_order=20.0), static=True)
        self.rec.log(st.coh.path, rr.Points2D.from_fields(radii=rr.Radius.ui_points(2.0), draw_order=21.0),
                     static=True)
        if st.wf_path is not None:
            self.rec.log(st.wf_path, rr.Tensor.from_fields(value_range=(0.0, 100.0)), static=True)
        return st

    def draw_all(self, w: np.ndarray, outputs: list, inputs: list, coh: np.ndarray, mag: np.ndarray,
                 pha: np.ndarray, coherence_kind: str) -> None:
        """Every pair's frequency plots and waterfall (the "All pairs" tab).

        Parameters
        ----------
        w : array (n_f,)
            Frequency grid [rad/s], > 0.
        outputs, inputs : list of str
        coh, mag, pha : arrays (n_out, n_in, n_f)
            gamma^2, |H| [dB] and phase [deg] (referenced here, :func:`reference_phase`).
        coherence_kind : str
            ``"ordinary"`` or ``"partial"``.
        """
        g = self.grid_batches(w)
        coherent = np.isfinite(coh) & (coh >= self.min_coherence)
        pha = reference_phase(pha, coherent)
        wf_pct = None
        if self.waterfall_rows:
            wf_pct = np.clip(np.rint(np.nan_to_num(coh, nan=0.0) * 100.0), 0, 100).astype(np.uint8)
        for io, o in enumerate(outputs):
            for ii, i in enumerate(inputs):
                st = self.pair(o, i)
                self.draw_pair(st, g, coh[io, ii], mag[io, ii], pha[io, ii], coherent[io, ii], coherence_kind)
                if wf_pct is not None:
                    row = wf_pct[io, ii][None, :]
                    old = st.waterfall
                    if old is None or old.shape[1] != w.size:
                        new = row.copy()
                    else:
                        keep = old[len(old) - (self.waterfall_rows - 1):] if self.waterfall_rows > 1 else old[:0]
                        new = np.concatenate([keep, row])
                    st.waterfall = new   # a new array every time: the logged one is never mutated
                    st.wf_count += 1
                    if st.wf_count == 1 or st.wf_count % self.waterfall_every == 0:
                        tensor = ArrowBatch(self.arrays.tensor(new, g["dims"]))
                        self.rec.log(st.wf_path, [rr.DescribedComponentBatch(tensor, self._d_tensor)])

    def draw_pair(self, st: PairState, g: dict, c: np.ndarray, mag: np.ndarray, pha: np.ndarray,
                  ok: np.ndarray, coherence_kind: str) -> None:
        """One pair's three plots on the frequency grid ``g`` (:meth:`grid_batches`, or at least its
        ``"logw"`` and ``"x"``); ``c`` gamma^2, ``mag`` [dB], ``pha`` [deg] already referenced
        (:func:`reference_phase`), ``ok`` where gamma^2 >= the threshold."""
        DCB = rr.DescribedComponentBatch
        logw, x_range = g["logw"], g["x"]
        fin = np.isfinite(c)
        pos = np.empty((int(fin.sum()), 2), np.float32)
        pos[:, 0] = logw[fin]
        pos[:, 1] = c[fin]
        pcol = np.where(ok[fin], _rgba(_COH_COLOR), _rgba(_MASKED_COLOR)).astype(np.uint32)
        points = self.arrays.points(pos)
        self._log_frame(st.coh, x_range, "γ² " + coherence_kind)
        self._log_curve(st.coh, logw, c, ok, [
            DCB(ArrowBatch(points), self._d_points), DCB(ArrowBatch(pa.array(pcol)), self._d_point_colors),
            DCB(ArrowBatch(pa.array(c)), self._d_coh_values),
            DCB(ArrowBatch(pa.array([coherence_kind], pa.string())), self._d_coh_kind)])
        for plot, y, label in ((st.mag, mag, "|H| dB"), (st.phase, pha, "phase deg")):
            lo, hi = _curve_range(y, ok, turns=plot is st.phase)
            plot.extent = value_extent(plot.extent, lo, hi, plot.steps)
            if plot.extent is None:
                continue      # nothing finite yet: nothing to draw
            self._log_frame(plot, x_range, label)
            self._log_curve(plot, logw, y, ok)

    def grid_batches(self, omega: np.ndarray) -> dict:
        """Per-frequency-grid values (``log10 omega``, the x range, the waterfall's dimension
        names), built once per grid ``omega`` [rad/s] and shared by every pair and update."""
        key = omega.tobytes()
        if self._grid_cache is not None and self._grid_cache[0] == key:
            return self._grid_cache[1]
        x0, x1 = frequency_extent(omega)
        g = {
            "key": key,
            "logw": np.log10(omega),
            "x": (x0, x1),
            "dims": ("estimate (newest last)",
                     f"frequency bin (0: {omega[0]:.3g} ... {omega.size - 1}: {omega[-1]:.3g} rad/s)"),
        }
        self._grid_cache = (key, g)
        return g

    def _log_frame(self, plot: _Plot, x_range: tuple[float, float], label: str) -> None:
        """The plot's display transform and grid, logged at the current time when they change.

        The transform maps the data box [x0, x1] x [y0, y1] (log10 rad/s, value) onto the plot box
        (:func:`plot_box`, y down); the grid (a child entity, so under the same transform) has a
        line at every 1-2-5 frequency and every value step, frequency labels under the box,
        value labels left of it and the axis name above them.
        """
        y0, y1, step = plot.extent
        key = (x_range, plot.extent, label)
        if key == plot.grid_key:
            return
        plot.grid_key = key
        x0, x1 = x_range
        bx, by, w, h = plot.box
        sx, sy = w / (x1 - x0), h / (y1 - y0)
        self.rec.log(plot.path, rr.Transform3D(translation=[bx - x0 * sx, by + y1 * sy, 0.0], scale=[sx, -sy, 1.0]))
        left, _, top, bottom = plot.margins
        below, beside, above = y0 - 0.4 * bottom / sy, x0 - 0.5 * left / sx, y1 + 0.6 * top / sy
        major, minor, pts, labels = [], [], [], []
        ticks = log_ticks(x0, x1)
        for k, (x, is_decade) in enumerate(ticks):
            (major if is_decade else minor).append([[x, y0], [x, y1]])
            pts.append([x, below])
            labels.append(tick_label(10.0 ** x) + (" rad/s" if k == len(ticks) - 1 else ""))
        n = int(round((y1 - y0) / step))
        for k in range(n + 1):
            yy = y0 + k * step
            (major if k in (0, n) or plot.kind != "coherence" else minor).append([[x0, yy], [x1, yy]])
            pts.append([beside, yy])
            labels.append(tick_label(yy))
        pts.append([beside, above])
        labels.append(label)
        self.rec.log(f"{plot.path}/grid",
                     rr.LineStrips2D(major + minor,
                                     colors=[_GRID_COLOR] * len(major) + [_GRID_MINOR_COLOR] * len(minor),
                                     radii=rr.Radius.ui_points(0.5), draw_order=5.0),
                     rr.Points2D(pts, labels=labels, show_labels=True, radii=rr.Radius.ui_points(0.5),
                                 colors=[_GRID_COLOR], draw_order=6.0))
        if plot.kind == "coherence":
            self.rec.log(f"{plot.path}/threshold",
                         rr.LineStrips2D([[[x0, self.min_coherence], [x1, self.min_coherence]]], colors=[_THRESHOLD_COLOR],
                                         radii=rr.Radius.ui_points(1.0), labels=[f"γ² = {self.min_coherence:g}"],
                                         show_labels=False, draw_order=15.0))

    def _log_curve(self, plot: _Plot, logw: np.ndarray, y: np.ndarray, coherent: np.ndarray,
                   extra: list | None = None) -> None:
        """One curve: coherent stretches in the plot's colour, masked ones grey and thin (see
        :func:`masked_runs`; a masked point outside the plotted range is not drawn)."""
        y0, y1, _ = plot.extent
        runs = masked_runs(y, coherent, (y0, y1))
        xy = np.empty((y.size, 2), np.float32)
        xy[:, 0] = logw
        xy[:, 1] = y
        strips = [xy[a:b] for a, b, _ in runs]
        good = np.array([ok for _, _, ok in runs], bool)
        colors = np.where(good, _rgba(plot.color), _rgba(_MASKED_COLOR)).astype(np.uint32)
        radii = np.where(good, _CURVE_RADIUS, _MASKED_RADIUS).astype(np.float32)
        DCB = rr.DescribedComponentBatch
        batches = [DCB(ArrowBatch(self.arrays.strips(strips)), self._d_strips),
                   DCB(ArrowBatch(pa.array(colors)), self._d_strip_colors),
                   DCB(ArrowBatch(pa.array(radii)), self._d_strip_radii)]
        self.rec.log(plot.path, batches + (extra or []))


def _curve_range(y: np.ndarray, coherent: np.ndarray, *, turns: bool = False) -> tuple[float, float]:
    """The range one curve needs: its coherent finite values, or all its finite values when fewer
    than two are coherent; (inf, -inf) when nothing is finite. With ``turns`` (a phase) of a pair
    coherent over less than half its points, at most two turns about the median of those values:
    the chance-coherent islands of an unexcited pair, which walk through many turns, must not set
    an axis of thousands of degrees (a response coherent over the band keeps all its turns)."""
    fin = np.isfinite(y)
    use = fin & coherent
    if use.sum() < 2:
        use = fin
    if not use.any():
        return math.inf, -math.inf
    v = y[use]
    lo, hi = float(v.min()), float(v.max())
    if turns and hi - lo > 720.0 and (fin & coherent).sum() < 0.5 * fin.sum():
        mid = float(np.median(v))
        lo, hi = max(lo, mid - 360.0), min(hi, mid + 360.0)
    return lo, hi
