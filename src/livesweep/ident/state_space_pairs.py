"""Which frequency-response pairs a state-space model is fitted to (docs/method.md §8.2).

:func:`select_pairs` takes every output/input pair the model covers from a
:class:`~livesweep.spectral.response.FrequencyResponseSet`, each over its band (the case's, or the
widest coherent stretch) at its fitting points (:func:`livesweep.ident.cost.fit_points`), and says
why it skips the others. :func:`a_priori_eliminations` names the control derivatives whose pairs
have no usable coherence, to remove before fitting. Frequencies in rad/s.
"""

from __future__ import annotations

import math

import numpy as np

from livesweep.errors import ConfigError
from livesweep.ident.cost import MIN_COHERENCE, N_OMEGA, fit_points, select_band
from livesweep.ident.state_space_model import StateSpaceModel
from livesweep.ident.state_space_table import _MATRICES

__all__ = ["select_pairs", "a_priori_eliminations"]


def select_pairs(frs, model: StateSpaceModel, *, bands: dict | None = None, min_coherence: float = MIN_COHERENCE,
                 omega_range=None, min_decades: float = 0.3, n_omega: int = N_OMEGA):
    """The model's pairs from a frequency-response set, at their fitting points.

    Parameters
    ----------
    frs : FrequencyResponseSet
        Usually the MISO-conditioned set.
    model : StateSpaceModel
    bands : dict of (output, input) -> (lo, hi), optional
        Per-pair bands [rad/s]; overrides the model's ``bands``. Other pairs take the widest
        contiguous stretch with coherence >= ``min_coherence``.
    min_coherence : float
        Coherence defining a pair's band when none is given.
    omega_range : (float, float), optional
        Frequencies outside which no coherence-selected band may reach [rad/s] (e.g. to keep
        out closed-loop-dominated low frequencies); explicit ``bands`` are not clipped.
    min_decades : float
        Coherence-selected bands narrower than this (after clipping) are skipped as unusable.

    Returns
    -------
    pairs : list of PairData
    skipped : list of (output, input, reason)
        Pairs the model covers but the data cannot support (not in the set, or no band with
        usable coherence).
    """
    bands = {**model.bands, **(bands or {})}
    pairs, skipped = [], []
    for o in model.outputs:
        for i in model.inputs:
            if o not in frs.outputs or i not in frs.inputs:
                skipped.append((o, i, "not in the frequency-response set"))
                continue
            resp = frs.pair(o, i)
            band = bands.get((o, i))
            if band is None:
                band = select_band(resp, min_coherence)
                if band is None:
                    skipped.append((o, i, f"no band with coherence >= {min_coherence:g}"))
                    continue
                if omega_range is not None:
                    band = (max(band[0], float(omega_range[0])), min(band[1], float(omega_range[1])))
                if band[1] <= band[0] or math.log10(band[1] / band[0]) < min_decades:
                    skipped.append((o, i, f"coherent band ({band[0]:.3g}-{band[1]:.3g} rad/s) narrower than "
                                          f"{min_decades:g} decade"))
                    continue
            try:
                pd = fit_points(resp, band, n_omega, min_coherence)
            except ConfigError as exc:
                skipped.append((o, i, str(exc)))
                continue
            if _no_path(model, o, i, pd.omega):
                skipped.append((o, i, "the model has no path from this input to this output (response identically "
                                      "zero) though the data are coherent: a coupling the model lacks?"))
                continue
            pairs.append(pd)
    return pairs, skipped


def _no_path(model: StateSpaceModel, output: str, input: str, omega) -> bool:
    """Whether the model's response ``output/input`` is identically zero by its structure (zero at
    the initial values and at other generic ones): it has no magnitude in dB to fit."""
    i, j = model.outputs.index(output), model.inputs.index(input)
    th0 = np.asarray(model.initial, float)
    for th in (th0, 1.1 * th0 + 0.1):
        with np.errstate(all="ignore"):
            try:
                T = model.frequency_response(th, omega)[i, j]
            except np.linalg.LinAlgError:
                return False
        if not np.all(T == 0.0):
            return False
    return True


def a_priori_eliminations(model: StateSpaceModel, skipped_pairs) -> dict:
    """Control derivatives to remove before fitting because their pairs have no coherence.

    docs/method.md §8.2: pairs with near-zero coherence are dropped and "the matching derivatives can
    be removed a priori". A parameter is matched to the skipped pair ``y/u_j`` when it appears only
    in column ``j`` of ``G`` (and of ``J``) at a state ``x_s`` that output ``y`` measures directly
    (the ``H`` row of ``y`` is a constant multiple of ``x_s`` alone, e.g. ``p`` of roll rate), and
    every output measuring ``x_s`` directly lost its pair with ``u_j``.

    Parameters
    ----------
    model : StateSpaceModel
    skipped_pairs : iterable of (output, input, ...)

    Returns
    -------
    dict of str -> str
        Parameter -> reason, for :meth:`~livesweep.ident.state_space.StateSpaceModel.with_values` (fix at 0).
    """
    skipped = {(t[0], t[1]) for t in skipped_pairs}
    theta = model.initial
    direct = {}                                            # state index -> outputs measuring it alone
    for r, o in enumerate(model.outputs):
        nz = [j for j, e in enumerate(model.H[r]) if not (e.is_constant and e.value(theta) == 0.0)]
        if len(nz) == 1 and model.H[r][nz[0]].is_constant:
            direct.setdefault(nz[0], []).append(o)
    where_used = {}
    for key in _MATRICES:
        for i, row in enumerate(getattr(model, key)):
            for j, e in enumerate(row):
                for name in e.parameters:
                    where_used.setdefault(name, set()).add((key, i, j))
    for j, e in enumerate(model.delay_entries):
        for name in e.parameters:
            where_used.setdefault(name, set()).add(("tau", 0, j))
    out = {}
    for name in model.free_names:
        uses = where_used.get(name, set())
        if not uses or any(k not in ("G", "J") for k, _, _ in uses):
            continue
        cols = {j for _, _, j in uses}
        g_states = {i for k, i, _ in uses if k == "G"}
        if len(cols) != 1 or len(g_states) != 1:
            continue
        j, s_ = cols.pop(), g_states.pop()
        outs = direct.get(s_, [])
        u = model.inputs[j]
        if outs and all((o, u) in skipped for o in outs):
            out[name] = (f"pair(s) {', '.join(f'{o}/{u}' for o in outs)} without usable coherence: "
                         f"{model.states[s_]} response to {u} not measurable")
    return out
