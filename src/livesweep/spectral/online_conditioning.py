"""MISO and referenced conditioning of the online estimate, computed from its running sums.

One job: condition targets (outputs, or inputs and outputs for the referenced legs) on a set of
conditioning signals (the inputs, or the references) at every frequency of one window, from the
spectral blocks :class:`~livesweep.spectral.online_result.OnlineResult` reads off the running sums.
:func:`_condition_many` does every target at once through one inverse of the conditioning signals'
coherence matrix per frequency; :func:`_condition` is the per-block path
(:func:`livesweep.spectral.miso.condition_blocks`) that survives a singular block, used for the
targets the fast path hands back. :func:`_nan_conditioned` is the "nothing conditioned" answer and
:func:`_max_pair_coherence` the cross-coherence of the conditioning signals that flags
ill-conditioned frequencies.
"""

from __future__ import annotations

import numpy as np

from livesweep.spectral.miso import condition_blocks


def _condition(S, q, max_input_coherence, n_segments):
    """:func:`livesweep.spectral.miso.condition_blocks` of one (q+1)x(q+1) block over (inputs,
    output), surviving a singular spectral matrix.

    With fewer segments than inputs + 1 the block has rank < q+1 at every frequency (nothing can
    be conditioned yet); exactly collinear signals make it singular at some. Those frequencies get
    H = NaN, coherences 0 and the ill-conditioned flag, instead of an exception.
    """
    n_f = S.shape[-1]
    nan = (np.full((q, n_f), np.nan + 0j), np.zeros((q, n_f)), np.zeros(n_f), np.ones(n_f, bool))
    if n_segments < q + 1:
        return nan
    try:
        c = condition_blocks(S, q, max_input_coherence=max_input_coherence)
        return c.H, c.partial_coherence, c.multiple_coherence, c.ill_conditioned
    except np.linalg.LinAlgError:
        H, pc, mc, ill = (a.copy() for a in nan)
        for f in range(n_f):
            try:
                c = condition_blocks(S[:, :, f:f + 1], q, max_input_coherence=max_input_coherence)
            except np.linalg.LinAlgError:
                continue
            H[:, f], pc[:, f], mc[f], ill[f] = c.H[:, 0], c.partial_coherence[:, 0], c.multiple_coherence[0], \
                c.ill_conditioned[0]
        return H, pc, mc, ill


def _nan_conditioned(n_targets, q, n_f):
    """Nothing conditioned: H NaN, coherences 0, every frequency flagged."""
    return (np.full((n_targets, q, n_f), np.nan + 0j), np.zeros((n_targets, q, n_f)), np.zeros((n_targets, n_f)),
            np.ones(n_f, bool))


def _max_pair_coherence(Gcc, acc) -> np.ndarray:
    """Largest ordinary coherence ``|G_ij|^2 / (G_ii G_jj)`` between two of the signals of the
    spectral block ``Gcc`` (q, q, f) with autospectra ``acc`` (q, f), per frequency; 1 where a
    signal has no power, 0 for one signal (:func:`livesweep.spectral.miso.input_coherence_max`)."""
    q = acc.shape[0]
    if q < 2:
        return np.zeros(acc.shape[-1])
    a, b = np.triu_indices(q, 1)
    g = Gcc[a, b]
    den = acc[a] * acc[b]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(den > 0, (g.real**2 + g.imag**2) / den, 1.0)
    return np.clip(c, 0.0, 1.0).max(axis=0)


def _condition_many(Gcc, Gct, acc, att, n_segments, ill_cond):
    """Every target conditioned on the same q signals at once (method.md §6): the arithmetic of
    :func:`livesweep.spectral.miso.condition_blocks` on each (q+1)x(q+1) block over (conditioning
    signals, target), through the block inverse, so that one inverse per frequency serves every
    target.

    With ``R = D^-1 Gcc D^-1`` (the conditioning signals' coherence matrix, ``D`` their root
    autospectra), ``r`` the target's cross-spectra scaled the same way and by its own root
    autospectrum, ``P = R^-1`` and ``b = P r``: the block's inverse ``C`` (scaled to unit diagonal)
    has ``C_yy = 1 / (1 - m)``, ``C_iy = -b_i C_yy``, ``C_ii = P_ii + |b_i|^2 C_yy`` with ``m = r^H b``,
    so the multiple coherence is ``m``, the partial coherence ``|b_i|^2 / ((1 - m) P_ii + |b_i|^2)``
    and ``H = Gcc^-1 Gct = D^-1 b sqrt(G_yy)``.

    Parameters
    ----------
    Gcc : ndarray, complex, shape (q, q, f)
        Spectral matrix of the conditioning signals (conjugate on the first index).
    Gct : ndarray, complex, shape (q, T, f)
        Their cross-spectra with the targets.
    acc, att : ndarray, shape (q, f) and (T, f)
        Autospectra (the same scale as ``Gcc`` and ``Gct``).
    n_segments : int
        Segments averaged (fewer than q + 1: nothing can be conditioned).
    ill_cond : ndarray of bool, shape (f,)
        Frequencies flagged ill-conditioned by the conditioning signals' cross-coherence.

    Returns
    -------
    (H, pc, mc, ill, redo) or None
        ``H``, ``pc`` (T, q, f), ``mc`` (T, f), ``ill`` (f,): where a signal of a block has no power
        H is NaN, the coherences 0 and the frequency flagged (as ``condition_blocks``); ``redo``:
        targets whose block is singular somewhere (``1 - m <= 0``), to be conditioned on their own.
        None when ``Gcc`` itself is singular at some frequency.
    """
    q, T, n_f = Gcc.shape[0], Gct.shape[1], Gcc.shape[-1]
    if n_segments < q + 1:
        return _nan_conditioned(T, q, n_f) + ((),)
    dx, dy = np.sqrt(acc), np.sqrt(att)
    everywhere = dx.min() > 0 and dy.min() > 0                  # the usual case: every signal has power
    if everywhere:
        f, ill = slice(None), ill_cond.copy()
    else:
        ok_x = np.all(dx > 0, axis=0)                           # (f,): every conditioning signal has power
        ok = ok_x & (dy > 0)                                    # (T, f): so has the target
        if not ok.any():
            return _nan_conditioned(T, q, n_f) + ((),)
        f, ill = np.flatnonzero(ok_x), ill_cond | ~ok.all(axis=0)
        dx, dy, Gcc, Gct = dx[:, f], dy[:, f], Gcc[..., f], Gct[..., f]
    with np.errstate(divide="ignore", invalid="ignore"):
        ix, iy = 1.0 / dx, 1.0 / dy
        Rm = np.moveaxis(Gcc * (ix[:, None, :] * ix[None, :, :]), -1, 0)      # (F, q, q), unit diagonal
        r = np.moveaxis(Gct * (ix[:, None, :] * iy[None, :, :]), -1, 0)        # (F, q, T)
    d = np.arange(q)
    Rm[:, d, d] = 1.0
    try:
        P = np.linalg.inv(Rm)
    except np.linalg.LinAlgError:
        return None
    b = P @ r                                                   # (F, q, T)
    m = np.einsum("fqt,fqt->ft", r.real, b.real)                # multiple coherence Re(r^H b), (F, T)
    m += np.einsum("fqt,fqt->ft", r.imag, b.imag)
    res = 1.0 - m                                               # 1 / C_yy: the unexplained fraction
    b2 = b.real**2
    b2 += b.imag**2
    den = np.diagonal(P, axis1=1, axis2=2).real[:, :, None] * res[:, None, :]
    den += b2
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.divide(b2, den, out=b2)                          # partial coherence, (F, q, T)
        b *= (dy * ix[:, None, :]).transpose(2, 0, 1)          # H = D^-1 b sqrt(G_yy)
    np.clip(p, 0.0, 1.0, out=p)
    np.clip(m, 0.0, 1.0, out=m)
    H, pc, mc = b.transpose(2, 1, 0), p.transpose(2, 1, 0), m.T   # (T, q, F), (T, q, F), (T, F)
    okf = True if everywhere else ok[:, f]
    redo = () if res.min() > 0 else np.flatnonzero(np.any(okf & ~(res.T > 0), axis=1))
    if not everywhere:                                          # blanks where a signal has no power
        Hs, pcs, mcs = _nan_conditioned(T, q, n_f)[:3]
        Hs[:, :, f] = np.where(okf[:, None, :], H, np.nan + 0j)
        pcs[:, :, f] = np.where(okf[:, None, :], pc, 0.0)
        mcs[:, f] = np.where(okf, mc, 0.0)
        H, pc, mc = Hs, pcs, mcs
    return H, pc, mc, ill, redo

