"""The residual loop in words: each added effect on one line, and the loop's conclusion.

:func:`effect_text` and :func:`model_effects` read an effect as report.json holds it (a dict, or a
:class:`~livesweep.ident.residual_records.EffectRecord`, which reads the same), so the console, the HTML
report and a report.json read back all say the same.
"""

from __future__ import annotations

from livesweep.ident.accuracy import pct_text

__all__ = ["effect_text", "model_effects", "conclusion_text"]


def effect_text(effect: dict) -> str:
    """One line for an added effect: ``"structural_mode at p: w_mode_p = 12.01 (CR 0.9 %), zeta_mode_p
    = 0.05158 (fixed: poorly determined), ..."``, and the effects it could not be told from."""
    def par(p):
        if p.get("fixed"):
            return f"{p['name']} = {p['value']:.4g} (fixed: poorly determined)"
        cr = pct_text(p["cramer_rao_pct"], ".4g")
        return f"{p['name']} = {p['value']:.4g} (CR {cr}{'' if cr == 'not determined' else ' %'})"
    text = f"{effect['kind']} at {effect['where']}: " + ", ".join(par(p) for p in effect["parameters"])
    for w in effect.get("with", ()):
        text += f"; together with {w['kind']} at {w['where']}: " + ", ".join(par(p) for p in w["parameters"])
    for a in effect.get("ambiguous_with", ()):
        text += f"; hard to tell from {a['kind']} at {a['where']} in this band"
    if "removes" in effect:
        r = effect["removes"]
        text += f"; took out {r['kind']} at {r['where']}, added before: {r['reason']}"
    if "replaces" in effect:
        r = effect["replaces"]
        text += (f"; replaced {r['kind']} at {r['where']}, added before, by {r['by']['kind']} at {r['by']['where']}: "
                 + ", ".join(par(p) for p in r["by"]["parameters"]) + f" ({r['reason']})")
    if "removed" in effect:
        r = effect["removed"]
        how = f"replaced by {r['replaced_by']}" if r.get("replaced_by") else "taken out"
        text += f" ({how} at step {r['at_step']}: {r['reason']})"
    return text


def model_effects(effects) -> list[dict]:
    """The effects in the final model from the steps' ``effect`` records (None for a step that
    added nothing), in the order added: each step's effect, the partners of a pair as their own
    entries, and the simpler effect a step put in an earlier one's place
    (:func:`~livesweep.ident.residual_backward.rechoose`);
    none that a later step took out or replaced (``removed``). Works on the records of a
    :class:`~livesweep.ident.residual.ResidualLoop` and on those read back from report.json."""
    return [e for eff in effects if eff is not None
            for e in (eff, *eff.get("with", ()), *((eff["replaces"]["by"],) if eff.get("replaces") else ()))
            if "removed" not in e]


def conclusion_text(added, removed, any_significant: bool, limits) -> str:
    """The loop's conclusion: what was added (and what it could not be told from), what was
    taken out or replaced, what could not be re-tested; or why nothing was; and the scale errors
    the data cannot show.

    Parameters
    ----------
    added : sequence of EffectRecord
        The effects in the final model, in the order added.
    removed : sequence of EffectRecord
        The steps' own effects a later step took out or replaced.
    any_significant : bool
        The last screen found something significant (or the fit inadequate).
    limits : sequence of dict
        kind, where, smallest_detectable_pct of each scale error the data cannot show.
    """
    if added:
        text = "added " + "; ".join(
            f"{e.kind} at {e.where}" + "".join(f" (hard to tell from {a['kind']} at {a['where']} in this band)"
                                                for a in e.ambiguous_with)
            for e in added)
        text += "".join(f"; took out {e.kind} at {e.where} added before ({e.removed['reason']})"
                        for e in removed if not e.removed.get("replaced_by"))
        text += "".join(f"; {e.kind} at {e.where} added before replaced by {e.removed['replaced_by']} "
                        f"({e.removed['reason']})" for e in removed if e.removed.get("replaced_by"))
        text += "".join(f"; could not re-test {u['kind']} at {u['where']} once {e.kind} at {e.where} was "
                        f"added ({u['error']}): kept" for e in added for u in e.not_retested)
    elif any_significant:
        text = "residual above noise, but no candidate effect passed the acceptance tests"
    else:
        text = "nothing to add: residual within noise"
    if limits:
        text += ("; scale errors these data cannot show (the derivatives absorb them): "
                 + ", ".join(f"{x['where']} " + ("any size" if x["smallest_detectable_pct"] >= 100 else
                                                 f"up to {x['smallest_detectable_pct']:.0f} %")
                             for x in sorted(limits, key=lambda x: -x["smallest_detectable_pct"])))
    return text
