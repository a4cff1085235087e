"""The residual loop's decision rules on records in their dict form (report.json's).

The loop judges :class:`~livesweep.ident.residual_records.Trial` records; these take the same
records as plain dicts (``{"kind", "where", "ss_before", "evidence_after", "parameters", ...}``) and
write a verdict back into the dict given, for callers that hold them so.
"""

from __future__ import annotations

from livesweep.ident.residual_backward import HistoryEntry, backward_step
from livesweep.ident.residual_choice import choose as _choose_trial, pair_refusal, rivals as _rivals_of
from livesweep.ident.residual_records import Trial

__all__ = ["choose", "rivals", "partners_needed", "backward"]


def choose(accepted, judge, n_model):
    """:func:`~livesweep.ident.residual_choice.choose` on ``(record dict, result)`` pairs: the
    chosen pair (the one given), its record's ``reason`` extended when it was preferred to one
    that explains more; None when ``accepted`` is empty."""
    typed = [(Trial.from_dict(rec), new) for rec, new in accepted]
    got = _choose_trial(typed, judge, n_model)
    if got is None:
        return None
    chosen, note = got
    picked = next(a for a, t in zip(accepted, typed) if t is chosen)
    if note:
        picked[0]["reason"] += note
    return picked


def rivals(rec, tried, judge, n_model) -> list[dict]:
    """:func:`~livesweep.ident.residual_choice.rivals` of the record dict ``rec``, one of the
    record dicts ``tried``."""
    typed = {id(t): Trial.from_dict(t) for t in (rec, *tried)}
    return _rivals_of(typed[id(rec)], [typed[id(t)] for t in tried], judge, n_model)


def partners_needed(rec, alone, judge, n_model) -> None:
    """:func:`~livesweep.ident.residual_choice.pair_refusal` of the pair's record dict ``rec``
    (``alone``: each partner's record dict refitted alone, in the pair's order); a refused pair's
    ``accepted`` and ``reason`` are set in ``rec``."""
    refusal = pair_refusal(Trial.from_dict(rec), [a.get("evidence_after") for a in alone], judge, n_model)
    if refusal is not None:
        rec["accepted"] = False
        rec["reason"] = refusal


def backward(history, table, fit, ss_with, judge, progress):
    """:func:`~livesweep.ident.residual_backward.backward_step` on history entries as dicts
    (``{"table", "cands", "names", "simpler", "effect"}``)."""
    return backward_step([HistoryEntry.from_dict(h) for h in history], table, fit, ss_with, judge, progress)
