"""What the residual loop records: each re-identified candidate, each added effect, each step.

The records are frozen; a later step's verdict on an earlier record (an effect taken out, a reason
extended) is a new record put in its place. Each serialises to its ``report.json`` entry with
``to_dict()`` (docs/outputs.md, report.json ``residual_loop``), and reads like that entry
(``trial["kind"]``, ``"removed" in effect``) for code written against report.json, such as
:func:`~livesweep.ident.residual.effect_text`. Leaves that other modules produce stay the dicts they
are: parameter reports (:func:`~livesweep.ident.accuracy.parameter_report`), significance tests,
verification summaries.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from livesweep.ident.state_space import StateSpaceFit
from livesweep.numeric import finite_or_none

__all__ = ["EffectRecord", "Replacement", "Trial", "CouplingTrial", "ModelState", "LoopStep", "ResidualLoop",
           "added_effects"]


class _ReportEntry(Mapping):
    """Read access by report.json key: ``record[key]`` is ``record.to_dict()[key]``."""

    __slots__ = ()

    def to_dict(self) -> dict:
        raise NotImplementedError

    def __getitem__(self, key):
        return self.to_dict()[key]

    def __iter__(self):
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())


@dataclass(frozen=True, eq=False)
class EffectRecord(_ReportEntry):
    """An effect the loop added to the model (report.json ``steps[].effect``).

    Attributes
    ----------
    kind, where : str
        The catalogue entry and its place (an input, an output, a matrix entry).
    parameters : tuple of dict
        Its parameters (:func:`~livesweep.ident.accuracy.parameter_report`: name, value, CR%, I%,
        fixed).
    significance : dict or None
        The F-test of its refit (None for a partner of a pair, a coupling, a replacement).
    gives_a_path_for : tuple of str or None
        For a coupling: the pairs ``"output/input"`` the model had no path for.
    ambiguous_with : tuple of dict
        Rival explanations the data cannot tell from it (kind, where, ...).
    partners : tuple of EffectRecord
        The other effects of a pair added together (report.json ``with``).
    not_retested : tuple of dict
        Earlier effects whose re-test failed once this one was in (kind, where, error).
    removes : dict or None
        The earlier effect this step took out (kind, where, reason).
    replaces : Replacement or None
        The earlier effect this step put a simpler rival in place of.
    removed : dict or None
        Set when a later step took this effect out (``at_step``, ``reason``) or replaced it
        (and ``replaced_by``).
    """

    kind: str
    where: str
    parameters: tuple = ()
    significance: dict | None = None
    gives_a_path_for: tuple | None = None
    ambiguous_with: tuple = ()
    partners: tuple = ()
    not_retested: tuple = ()
    removes: dict | None = None
    replaces: Replacement | None = None
    removed: dict | None = None

    def to_dict(self) -> dict:
        d = {"kind": self.kind, "where": self.where, "parameters": list(self.parameters)}
        if self.significance is not None:
            d["significance"] = self.significance
        if self.gives_a_path_for is not None:
            d["gives_a_path_for"] = list(self.gives_a_path_for)
        if self.ambiguous_with:
            d["ambiguous_with"] = list(self.ambiguous_with)
        if self.partners:
            d["with"] = [p.to_dict() for p in self.partners]
        if self.not_retested:
            d["not_retested"] = list(self.not_retested)
        if self.removes is not None:
            d["removes"] = self.removes
        if self.replaces is not None:
            d["replaces"] = self.replaces.to_dict()
        if self.removed is not None:
            d["removed"] = self.removed
        return d

    @classmethod
    def from_dict(cls, d) -> "EffectRecord":
        """The record from its report.json form (absent keys take their defaults)."""
        rep = d.get("replaces")
        if rep is not None:
            rep = Replacement(rep["kind"], rep["where"], cls.from_dict(rep["by"]), rep["reason"])
        return cls(d.get("kind", ""), d.get("where", ""), tuple(d.get("parameters", ())), d.get("significance"),
                   None if d.get("gives_a_path_for") is None else tuple(d["gives_a_path_for"]),
                   tuple(d.get("ambiguous_with", ())), tuple(cls.from_dict(w) for w in d.get("with", ())),
                   tuple(d.get("not_retested", ())), d.get("removes"), rep, d.get("removed"))


@dataclass(frozen=True, eq=False)
class Replacement(_ReportEntry):
    """An earlier effect a step replaced by a simpler rival (report.json ``effect.replaces``).

    Attributes
    ----------
    kind, where : str
        The earlier effect.
    by : EffectRecord
        The rival put in its place.
    reason : str
    """

    kind: str
    where: str
    by: EffectRecord
    reason: str

    def to_dict(self) -> dict:
        return {"kind": self.kind, "where": self.where, "by": self.by.to_dict(), "reason": self.reason}


@dataclass(frozen=True, eq=False)
class Trial(_ReportEntry):
    """A candidate effect (or a pair) added to the model, re-identified and judged (report.json
    ``steps[].tried[]``).

    Attributes
    ----------
    kind, where : str
        The effect (the first of a pair).
    evidence : float
        Its screened evidence (a pair's summed): the drop of the whitened sum of squares the
        screen expects.
    cost_before : float
        J_ave before it.
    ss_before : float
        The whitened sum of squares before it.
    fixed : tuple of dict
        Its parameter fixed at its fitted value, if any (name, value, cramer_rao_pct,
        insensitivity_pct, reason).
    accepted : bool
    reason : str
        Why not, or "accepted" and what was fixed (and what it was preferred to).
    cost_after : float
        J_ave of the refit (NaN when the model could not be re-identified).
    parameters : tuple of dict
        Its new parameters (:func:`~livesweep.ident.accuracy.parameter_report`); a pair's first
        effect's.
    identified : bool
        False when the model with it could not be built or fitted (``reason`` says why); the
        fields below are then unset.
    evidence_after : float or None
        The drop of the whitened sum of squares the refit gave.
    verification_after, verification_change : dict or None
        The refit's verification summary and its comparison with the model before.
    significance : dict or None
        The refit's F-test (:meth:`~livesweep.ident.selection.Significance.to_dict`).
    partners : tuple of EffectRecord or None
        A pair's other effects (report.json ``with``).
    shape_held : bool or None
        Whether its shape held: converged, significant, J_ave down, verification not worse
        (whatever its parameters' accuracy).
    ambiguous_with : tuple of dict or None
        Set on the effect chosen at its step: the rivals it cannot be told from.
    candidates : tuple of Candidate
        The screened candidates it was made of (not in report.json).
    """

    kind: str
    where: str
    evidence: float
    cost_before: float
    ss_before: float
    accepted: bool
    reason: str
    cost_after: float
    parameters: tuple = ()
    fixed: tuple = ()
    identified: bool = True
    evidence_after: float | None = None
    verification_after: dict | None = None
    verification_change: dict | None = None
    significance: dict | None = None
    partners: tuple | None = None
    shape_held: bool | None = None
    ambiguous_with: tuple | None = None
    candidates: tuple = field(default=(), repr=False)

    def to_dict(self) -> dict:
        d = {"kind": self.kind, "where": self.where, "evidence": self.evidence, "cost_before": self.cost_before,
             "ss_before": self.ss_before, "fixed": list(self.fixed)}
        if not self.identified:
            d.update(accepted=self.accepted, reason=self.reason, cost_after=self.cost_after,
                     parameters=list(self.parameters))
            return d
        d.update(cost_after=self.cost_after, evidence_after=self.evidence_after, parameters=list(self.parameters),
                 verification_after=self.verification_after, verification_change=self.verification_change,
                 significance=self.significance)
        if self.partners is not None:
            d["with"] = [p.to_dict() for p in self.partners]
        d.update(shape_held=self.shape_held, accepted=self.accepted, reason=self.reason)
        if self.ambiguous_with is not None:
            d["ambiguous_with"] = list(self.ambiguous_with)
        return d

    @classmethod
    def from_dict(cls, d) -> "Trial":
        """The record from its report.json form (absent keys take their defaults; the candidates
        are not in it)."""
        nan = float("nan")
        return cls(d.get("kind", ""), d.get("where", ""), d.get("evidence", nan), d.get("cost_before", nan),
                   d.get("ss_before", nan), d.get("accepted", False), d.get("reason", ""), d.get("cost_after", nan),
                   tuple(d.get("parameters", ())), tuple(d.get("fixed", ())), "evidence_after" in d,
                   d.get("evidence_after"), d.get("verification_after"), d.get("verification_change"),
                   d.get("significance"),
                   None if "with" not in d else tuple(EffectRecord.from_dict(w) for w in d["with"]),
                   d.get("shape_held"), None if "ambiguous_with" not in d else tuple(d["ambiguous_with"]))


@dataclass(frozen=True, eq=False)
class CouplingTrial(_ReportEntry):
    """An absent entry tried to give a coherent pair a path (report.json ``steps[].tried[]`` of a
    coupling step).

    Attributes
    ----------
    kind : str
        ``"missing_derivative"``.
    where : str
        The entry (``"F[row][col]"``, ``"G[row][col]"``) or the freed parameter.
    cost_after : float or None
        J_ave of the refit on every pair (None when it failed).
    accepted : bool
    reason : str
    parameters : tuple of dict
        The new parameter (none when the refit failed).
    """

    kind: str
    where: str
    cost_after: float | None
    accepted: bool
    reason: str
    parameters: tuple = ()

    def to_dict(self) -> dict:
        return {"kind": self.kind, "where": self.where, "cost_after": self.cost_after, "accepted": self.accepted,
                "reason": self.reason, "parameters": list(self.parameters)}


@dataclass(frozen=True, eq=False)
class ModelState:
    """A model the loop holds or tried: its table (values = fit), fit, verification and residuals.

    Attributes
    ----------
    table : dict
        The ``[state_space]`` table, parameter values at the fit's.
    fit : StateSpaceFit
    verification : Verification or list of Verification or None
        From the loop's verification callback, when given.
    residuals : tuple of PairResidual
        On the loop's pairs.
    """

    table: dict
    fit: StateSpaceFit
    verification: object
    residuals: tuple


@dataclass(frozen=True)
class LoopStep:
    """One step of the residual loop (docs/outputs.md, report.json ``residual_loop.steps``).

    Attributes
    ----------
    candidates : tuple of Candidate
        The ranking before this step (best first).
    tried : tuple of Trial or CouplingTrial
        Each re-identified candidate (kind, where, cost_after, evidence_after, verification_after,
        parameters (name, value, CR%, I%), accepted, reason, ...), read like its report.json dict.
    effect : EffectRecord or None
        The accepted effect (kind, where, parameters, ...), None when nothing was accepted.
    cost_before, cost_after : float
        J_ave before and after (after = before when nothing was accepted).
    verification_before, verification_after : dict or None
        ``{"j_rms", "tic": {output: value}}`` from the verification callback.
    residuals_before, residuals_after : tuple of PairResidual
    """

    candidates: tuple
    tried: tuple
    effect: EffectRecord | None
    cost_before: float
    cost_after: float
    verification_before: dict | None
    verification_after: dict | None
    residuals_before: tuple
    residuals_after: tuple

    def to_dict(self) -> dict:
        return {"effect": None if self.effect is None else self.effect.to_dict(),
                "cost_before": round(self.cost_before, 4), "cost_after": round(self.cost_after, 4),
                "verification_before": self.verification_before, "verification_after": self.verification_after,
                "candidates": [c.to_dict() for c in self.candidates[:8]],
                "tried": [{**t.to_dict(), "cost_after": finite_or_none(t.cost_after)} for t in self.tried]}


@dataclass(frozen=True)
class ResidualLoop:
    """Result of :func:`~livesweep.ident.residual.run_residual_loop`.

    Attributes
    ----------
    steps : tuple of LoopStep
        Accepted steps, then the final step that found nothing (or nothing acceptable). A step's
        effect carries ``removes`` (kind, where, reason) when the backward step took an earlier
        effect out after it was added, or ``replaces`` (kind, where, ``by``: the simpler effect put
        in its place, reason) when it put a simpler rival in an earlier effect's place; that
        earlier effect carries ``removed`` (why, at which step, ``replaced_by``).
    table : dict
        The final ``[state_space]`` table (with every accepted effect, values = final fit).
    fit : StateSpaceFit
        The final fit.
    unexplained : tuple of dict
        Pairs whose residual stays above noise (rms in noise units > 2) and candidates that had
        evidence but were rejected.
    conclusion : str
        One line: what was added, or "nothing to add: residual within noise".
    n_fits : int
        Re-identifications run.
    criterion : dict
        The selection criterion's settings: ``false_alarm``, ``effective_points`` (independent
        values in the fitted pairs), ``noise_inflation``.
    limits : tuple of dict
        Effects the data cannot show in this band (kind, where, smallest_detectable_pct): a scale
        factor the model's derivatives absorb is reported, not guessed.
    """

    steps: tuple
    table: dict
    fit: StateSpaceFit
    unexplained: tuple
    conclusion: str
    n_fits: int
    limits: tuple = ()
    criterion: dict = field(default_factory=dict)

    @property
    def added(self) -> tuple:
        """Every effect in the final model, in the order added (the partners of a pair added
        together as their own entries; one taken out at a later step, marked ``removed`` in its
        step, is not listed), as report.json dicts without ``with`` and ``replaces``."""
        return tuple({k: v for k, v in e.to_dict().items() if k not in ("with", "replaces")}
                     for e in added_effects(s.effect for s in self.steps))

    def to_dict(self) -> dict:
        return {"steps": [s.to_dict() for s in self.steps], "unexplained": list(self.unexplained),
                "conclusion": self.conclusion, "re_identifications": self.n_fits, "limits": list(self.limits),
                "criterion": self.criterion}


def added_effects(effects) -> list[EffectRecord]:
    """The effects in the final model from the steps' effects (None for a step that added
    nothing), in the order added: each step's effect, the partners of a pair as their own
    entries, and the simpler effect a step put in an earlier one's place; none that a later step
    took out or replaced. The records' form of :func:`~livesweep.ident.residual.model_effects`."""
    return [e for eff in effects if eff is not None
            for e in (eff, *eff.partners, *((eff.replaces.by,) if eff.replaces is not None else ()))
            if e.removed is None]
