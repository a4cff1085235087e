"""The residual-loop stage of ``livesweep identify``: diagnose what the identified model lacks,
add it, re-identify, and report before and after (``livesweep.ident.residual``).

The case's optional ``[residual]`` table::

    [residual]
    enabled = true                       # default true when the case has [state_space]
    max_steps = 3                        # effects added at most
    kinds = ["time_delay", "sensor_skew"]   # default: the whole catalogue
    min_evidence = { scale_factor = 400 }   # per-kind noise thresholds (default: measured ones)

Verification records of the case (``[[verify]]``) drive the time-domain test of every change.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.config import Case
from livesweep.errors import ConfigError
from livesweep.ident.residual import KINDS, MIN_EVIDENCE, ResidualLoop, run_residual_loop
from livesweep.spectral.response import FrequencyResponseSet

__all__ = ["ResidualStage", "residual_settings", "run_residual_stage"]

_KEYS = {"enabled", "max_steps", "kinds", "min_evidence"}


@dataclass(frozen=True)
class ResidualStage:
    """The loop's result, the settings it ran with and, when it added effects, the final model's
    verification per record (label, Verification) for the time-domain plots."""

    loop: ResidualLoop
    settings: dict
    verification_after: tuple = ()


def residual_settings(case: Case) -> dict:
    """Validated ``[residual]`` settings (defaults filled in); ConfigError naming file and key."""
    raw = case.tables.get("residual") or {}
    where = f"{case.path}: [residual]"
    if not isinstance(raw, dict):
        raise ConfigError(f"{where} must be a table")
    bad = sorted(set(raw) - _KEYS)
    if bad:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(bad)}; known: {', '.join(sorted(_KEYS))}")
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
    me = raw.get("min_evidence", {})
    if not isinstance(me, dict):
        raise ConfigError(f"{where}.min_evidence = {me!r}: must be a table of kind = number")
    for k, v in me.items():
        if k not in KINDS:
            raise ConfigError(f"{where}.min_evidence.{k}: unknown effect kind; known: {', '.join(KINDS)}")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise ConfigError(f"{where}.min_evidence.{k} = {v!r}: must be a positive number")
    return {"enabled": enabled, "max_steps": steps, "kinds": list(kinds),
            "min_evidence": {**MIN_EVIDENCE, **{k: float(v) for k, v in me.items()}}}


def _verifier(case: Case, sample_rate_hz: float, inputs, outputs):
    """A ``verify(model, theta)`` over the case's verification records (loaded once), or None."""
    from livesweep.ident.verify import verify
    from livesweep.pipeline.frequency_response import load_record

    if not case.verify:
        return None
    units = [case.signals[o].units if o in case.signals else "" for o in outputs]
    records = []
    for rec in case.verify:
        data = load_record(case, (rec,), [*inputs, *outputs], sample_rate_hz)
        u = np.vstack([data.signal(n) for n in inputs])
        records.append((data.t_s, np.where(np.isfinite(u), u, 0.0), np.vstack([data.signal(n) for n in outputs]),
                        data.all_valid()))

    def run(model, theta):
        M, F, G, H, J, tau = model.matrices(theta)
        tau_y, skews = model.output_delays_s(theta), model.input_skews_s(theta)
        return [verify(M, F, G, H, J, np.asarray(tau, float), t, u, y, output_names=list(outputs), output_units=units,
                       valid=valid, output_delays=tau_y, input_skews=skews) for t, u, y, valid in records]

    return run


def run_residual_stage(case: Case, frs: FrequencyResponseSet, ss, *, progress=None) -> ResidualStage | None:
    """Run the loop on the state-space stage's result; None when there is nothing to run it on."""
    if ss is None:
        return None
    settings = residual_settings(case)
    if not settings["enabled"]:
        return None
    model = ss.fit.model
    verify = _verifier(case, case.spectral.sample_rate_hz, tuple(model.inputs), tuple(model.outputs))
    loop = run_residual_loop(case.tables["state_space"], ss.fit, frs, verify=verify, max_steps=settings["max_steps"],
                             kinds=settings["kinds"], min_evidence=settings["min_evidence"], progress=progress)
    after = ()
    if verify is not None and loop.added:
        labels = [rec.label or rec.log.name for rec in case.verify]
        after = tuple(zip(labels, verify(loop.fit.model, loop.fit.theta)))
    return ResidualStage(loop, settings, after)
