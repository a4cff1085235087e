"""The parametric stages of ``livesweep identify``: transfer functions, state space, verification.

Glue between the case file, the frequency-response stage's results and the pure fitters in
``livesweep.ident``; every table the case names is validated here with errors naming file and key.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livesweep.config import Case
from livesweep.errors import ConfigError
from livesweep.ident.cost import fit_points
from livesweep.ident.handling import ATTITUDE_UNITS, RATE_UNITS, handling_qualities, response_kind
from livesweep.ident.transfer_function import fit_transfer_function
from livesweep.tf_tables import TransferFunctionSpec, specs_of_tables
from livesweep.spectral.response import FrequencyResponseSet

__all__ = ["TransferFunctionSpec", "TransferFunctionStage", "transfer_function_specs", "run_transfer_function_stage",
           "StateSpaceStage", "run_state_space_stage", "VerificationStage", "VerificationRunner",
           "run_verification_stage", "specs_of_tables",
           # the handling-qualities reading lives in livesweep.ident.handling; importable from here too
           "handling_qualities", "response_kind", "RATE_UNITS", "ATTITUDE_UNITS"]



@dataclass(frozen=True)
class TransferFunctionStage:
    """Fitted transfer functions, the data points each was fitted to, and handling qualities."""

    fits: tuple
    pairs: dict          # name -> PairData
    notes: tuple
    handling: dict = None   # name -> {"measured": {...}, "fitted": {...}}


def transfer_function_specs(case: Case) -> tuple[TransferFunctionSpec, ...]:
    """Every ``[transfer_functions.*]`` of the case, validated and parsed (ConfigError naming file
    and key, before any data is read)."""
    return specs_of_tables(case.tables.get("transfer_functions") or {}, case.path)


def run_transfer_function_stage(case: Case, frs: FrequencyResponseSet,
                                specs: tuple[TransferFunctionSpec, ...] | None = None) -> TransferFunctionStage | None:
    """Fit every ``[transfer_functions.*]`` of the case; models with the same denominator text
    are fitted together with a shared denominator (Tischler & Remple's Eq. 2.7). None when the case has none.

    ``specs``: the case's parsed tables (:func:`transfer_function_specs`; parsed here when not given).
    """
    specs = transfer_function_specs(case) if specs is None else specs
    if not specs:
        return None
    groups: dict[str, list] = {}
    pairs = {}
    for spec in specs:
        model = spec.model
        if model.output not in frs.outputs or model.input not in frs.inputs:
            raise ConfigError(f"{case.path}: transfer_functions.{model.name}: pair {model.output}/{model.input} is not "
                              f"among the frequency responses (outputs {list(frs.outputs)}, inputs {list(frs.inputs)})")
        pd = fit_points(frs.pair(model.output, model.input), band_rad_s=spec.band_rad_s,
                        min_coherence=case.criteria.min_coherence)
        groups.setdefault(str(model.denominator), []).append((pd, model))
        pairs[model.name] = pd
    fits, notes = [], []
    for members in groups.values():
        result = fit_transfer_function([pd for pd, _ in members], [m for _, m in members])
        for f in result:
            if not f.converged:
                notes.append(f"transfer function {f.name}: the fit did not converge ({f.message})")
        fits.extend(result)
    handling = {}
    for f in fits:
        resp = frs.pair(f.output, f.input)
        units = case.signals[f.output].units if f.output in case.signals else ""
        if response_kind(units) is None:
            continue
        handling[f.name] = {"measured": handling_qualities(resp.omega, resp.H, coherence=resp.coherence,
                                                           output_units=units,
                                                           min_coherence=case.criteria.min_coherence),
                            "fitted": handling_qualities(resp.omega, f.response(resp.omega), output_units=units)}
    return TransferFunctionStage(tuple(fits), pairs, tuple(notes), handling)


@dataclass(frozen=True)
class StateSpaceStage:
    """The fitted (and structure-reduced) state-space model."""

    model: object        # StateSpaceModel as written in the case
    fit: object          # StateSpaceFit after structure reduction
    full_fit: object     # StateSpaceFit before it
    skipped_pairs: tuple
    notes: tuple


def run_state_space_stage(case: Case, frs: FrequencyResponseSet, *, reduce: bool = True,
                          progress=None, model=None) -> StateSpaceStage | None:
    """Fit the case's ``[state_space]`` model to the frequency responses, then reduce its structure.

    None when the case has no ``[state_space]`` table. ``model``: the table already parsed
    (:class:`~livesweep.ident.state_space.StateSpaceModel`; parsed here when not given).
    """
    from livesweep.ident.state_space import (StateSpaceModel, a_priori_eliminations, fit_state_space,
                                             reduce_structure, select_pairs)

    table = case.tables.get("state_space")
    if not table:
        return None
    if model is None:
        model = StateSpaceModel.from_table(table, where=f"{case.path}: state_space")
    pairs, skipped = select_pairs(frs, model, min_coherence=case.criteria.min_coherence)
    if not pairs:
        raise ConfigError(f"{case.path}: state_space: none of the model's pairs has usable coherence")
    notes = [f"pair {o}/{i} not fitted: {why}" for o, i, why in skipped]
    eliminated = a_priori_eliminations(model, skipped)
    if eliminated:
        model = model.with_values(fixed={name: 0.0 for name in eliminated})
        notes += [f"{name} fixed at 0 a priori: {why}" for name, why in sorted(eliminated.items())]
    if progress:
        progress(f"state space: fitting {len(model.free_names)} parameters to {len(pairs)} pairs")
    full = fit_state_space(model, pairs, skipped_pairs=skipped)
    if not full.converged:
        notes.append(f"the state-space fit did not converge: {full.message}")
    fit = full
    if reduce:
        if progress:
            progress("state space: model-structure reduction")
        fit = reduce_structure(model, pairs, full)
    return StateSpaceStage(model, fit, full, tuple(skipped), tuple(notes))


@dataclass(frozen=True)
class VerificationStage:
    """Time-domain verification on the case's ``[[verify]]`` records, one result per record."""

    results: tuple       # (label, Verification)
    inputs: tuple
    outputs: tuple
    runner: object = None   # the VerificationRunner the results came from (records already loaded)
    notes: tuple = ()       # verification logs that were unfinished or recovered


class VerificationRunner:
    """The case's verification records, loaded once, and a model driven open loop over them.

    Parameters
    ----------
    case : Case
    sample_rate_hz : float
    inputs, outputs : sequence of str
        The model's inputs and outputs (signal names of the case).
    """

    def __init__(self, case: Case, sample_rate_hz: float, inputs, outputs):
        from livesweep.stages.frequency_response import load_record

        self.inputs, self.outputs = tuple(inputs), tuple(outputs)
        self.units = [case.signals[o].units if o in case.signals else "" for o in self.outputs]
        self.records = []
        self.notes: list[str] = []          # logs that were unfinished or recovered
        for rec in case.verify:
            data = load_record(case, (rec,), [*self.inputs, *self.outputs], sample_rate_hz, notes=self.notes)
            u = np.vstack([data.signal(n) for n in self.inputs])
            self.records.append((rec.label or rec.log.name, data.t_s, np.where(np.isfinite(u), u, 0.0),
                                 np.vstack([data.signal(n) for n in self.outputs]), data.all_valid()))

    def __call__(self, model, theta) -> list:
        """``[(label, Verification)]`` of ``model`` at ``theta`` on every record."""
        from livesweep.ident.verify import verify

        M, F, G, H, J, tau = model.matrices(theta)
        tau_y, skews = model.output_delays_s(theta), model.input_skews_s(theta)
        return [(label, verify(M, F, G, H, J, np.asarray(tau, float), t, u, y, output_names=list(self.outputs),
                               output_units=self.units, valid=valid, output_delays=tau_y, input_skews=skews))
                for label, t, u, y, valid in self.records]


def run_verification_stage(case: Case, ss: StateSpaceStage, sample_rate_hz: float) -> VerificationStage | None:
    """Drive the identified model open loop with each verification record's measured inputs."""
    if not case.verify or ss is None:
        return None
    model = ss.fit.model
    runner = VerificationRunner(case, sample_rate_hz, model.inputs, model.outputs)
    return VerificationStage(tuple(runner(model, ss.fit.theta)), runner.inputs, runner.outputs, runner,
                             tuple(runner.notes))
