"""The residual-loop stage of ``livesweep identify``: diagnose what the identified model lacks,
add it, re-identify, and report before and after (``livesweep.ident.residual``).

The case's optional ``[residual]`` table::

    [residual]
    enabled = true                       # default true when the case has [state_space]
    max_steps = 3                        # effects added at most
    kinds = ["time_delay", "sensor_skew"]   # default: the whole catalogue
    false_alarm = 0.01                   # probability per step of adding an effect to a clean log

Verification records of the case (``[[verify]]``) drive the time-domain test of every change.
"""

from __future__ import annotations

from dataclasses import dataclass

from livesweep.config import Case, require_table
from livesweep.errors import ConfigError
from livesweep.ident.residual import FALSE_ALARM, KINDS, ResidualLoop, run_residual_loop
from livesweep.ident.state_space import evaluate_state_space, select_pairs
from livesweep.stages.parametric import VerificationRunner
from livesweep.spectral.response import FrequencyResponseSet

__all__ = ["ResidualSettings", "ResidualStage", "residual_settings", "run_residual_stage"]

_KEYS = {"enabled", "max_steps", "kinds", "false_alarm", "min_evidence"}


@dataclass(frozen=True)
class ResidualStage:
    """The loop's result, the settings it ran with and, when it added effects, the final model.

    Attributes
    ----------
    loop : ResidualLoop
    settings : ResidualSettings
    verification_after : tuple of (label, Verification)
        The final model driven on each ``[[verify]]`` record (empty when nothing was added).
    final : StateSpaceFit or None
        When effects were added: the loop's final fit judged on the state-space stage's
        frequency points (:func:`~livesweep.ident.state_space.evaluate_state_space`), so its
        J_ave, Cramer-Rao bounds and insensitivities compare with the stage's. The loop itself
        judges each step on :data:`~livesweep.ident.residual.N_OMEGA_LOOP` points per pair.
    """

    loop: ResidualLoop
    settings: ResidualSettings
    verification_after: tuple = ()
    final: object = None


@dataclass(frozen=True)
class ResidualSettings:
    """The case's ``[residual]`` table, validated, defaults filled in.

    Attributes
    ----------
    enabled : bool
    max_steps : int
        Effects added at most (0-10).
    kinds : tuple of str
        Effect kinds searched (catalogue names).
    false_alarm : float
        Family-wise probability per step of adding an effect to a clean log, in (0, 0.2].
    """

    enabled: bool = True
    max_steps: int = 3
    kinds: tuple = tuple(KINDS)
    false_alarm: float = FALSE_ALARM

    def to_dict(self) -> dict:
        return {"enabled": self.enabled, "max_steps": self.max_steps, "kinds": list(self.kinds),
                "false_alarm": self.false_alarm}


def residual_settings(case: Case) -> ResidualSettings:
    """Validated ``[residual]`` settings (defaults filled in); ConfigError naming file and key."""
    where = f"{case.path}: [residual]"
    raw = require_table(case.tables.get("residual") or {}, _KEYS, where)
    enabled = raw.get("enabled", True)
    if not isinstance(enabled, bool):
        raise ConfigError(f"{where}.enabled = {enabled!r}: must be true or false")
    steps = raw.get("max_steps", 3)
    if isinstance(steps, bool) or not isinstance(steps, int) or not 0 <= steps <= 10:
        raise ConfigError(f"{where}.max_steps = {steps!r}: must be an integer from 0 to 10")
    kinds = raw.get("kinds", list(KINDS))
    if not isinstance(kinds, list) or not kinds:
        raise ConfigError(f"{where}.kinds = {kinds!r}: must be a non-empty list of effect kinds")
    for i, k in enumerate(kinds):
        if k not in KINDS:
            raise ConfigError(f"{where}.kinds[{i}] = {k!r}: unknown effect kind; known: {', '.join(KINDS)}")
    if "min_evidence" in raw:
        raise ConfigError(f"{where}.min_evidence: no longer used (per-kind thresholds measured on one simulator); "
                          f"the loop now tests significance, set false_alarm (default {FALSE_ALARM:g}) instead")
    fa = raw.get("false_alarm", FALSE_ALARM)
    if isinstance(fa, bool) or not isinstance(fa, (int, float)) or not 0 < fa <= 0.2:
        raise ConfigError(f"{where}.false_alarm = {fa!r}: must be a probability in (0, 0.2]")
    return ResidualSettings(enabled, steps, tuple(kinds), float(fa))


def run_residual_stage(case: Case, frs: FrequencyResponseSet, ss, *, runner=None,
                       progress=None, settings: ResidualSettings | None = None) -> ResidualStage | None:
    """Run the loop on the state-space stage's result; None when there is nothing to run it on.

    ``runner``: the verification stage's :class:`~livesweep.stages.parametric.VerificationRunner`
    (its records are already loaded); built here when not given and the case has ``[[verify]]``.
    ``settings``: the case's parsed ``[residual]`` (parsed here when not given).
    """
    if ss is None:
        return None
    settings = settings or residual_settings(case)
    if not settings.enabled:
        return None
    if runner is None and case.verify:
        model = ss.fit.model
        runner = VerificationRunner(case, case.spectral.sample_rate_hz, model.inputs, model.outputs)

    def verify(model, theta):
        return [v for _, v in runner(model, theta)]

    loop = run_residual_loop(case.tables["state_space"], ss.fit, frs, verify=verify if runner else None,
                             max_steps=settings.max_steps, kinds=list(settings.kinds),
                             false_alarm=settings.false_alarm, progress=progress,
                             min_coherence=case.criteria.min_coherence)
    if not loop.added:
        return ResidualStage(loop, settings)
    after = tuple(runner(loop.fit.model, loop.fit.theta)) if runner is not None else ()
    pairs, _ = select_pairs(frs, loop.fit.model, min_coherence=case.criteria.min_coherence)
    return ResidualStage(loop, settings, after, evaluate_state_space(loop.fit, pairs))
