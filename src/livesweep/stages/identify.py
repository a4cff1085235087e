"""``identify(case)``: the post-flight stages of one case, in order, as one frozen result.

The command line (``livesweep identify``), ``livesweep batch`` and the demo only present what this
returns; :func:`livesweep.report.writer.write_report` writes it to a folder.

Examples
--------
>>> import livesweep
>>> ident = livesweep.identify("config/xv15_cruise_lateral.toml", until="state-space")  # doctest: +SKIP
>>> ident.state_space.fit.cost_average                                                  # doctest: +SKIP
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from livesweep.config import Case, load_case
from livesweep.errors import ConfigError
from livesweep.stages import STAGES
from livesweep.stages.background import Background
from livesweep.stages.frequency_response import FrequencyResponseStage, run_frequency_response_stage
from livesweep.stages.live_models import read_live_models
from livesweep.stages.parametric import (StateSpaceStage, TransferFunctionStage, VerificationStage,
                                           run_state_space_stage, run_transfer_function_stage,
                                           run_verification_stage, transfer_function_specs)
from livesweep.stages.residual import ResidualSettings, ResidualStage, residual_settings, run_residual_stage

__all__ = ["STAGES", "CaseSpecs", "Identification", "identify", "parse_case_specs"]


@dataclass(frozen=True)
class CaseSpecs:
    """The stage tables of a case, parsed once into typed specs.

    Attributes
    ----------
    transfer_functions : tuple of TransferFunctionSpec
        ``[transfer_functions.*]`` (empty when the case has none).
    state_space : StateSpaceModel or None
        ``[state_space]`` as a model (initial values, fixed parameters, delays, bands).
    residual : ResidualSettings
        ``[residual]`` with defaults filled in.
    """

    transfer_functions: tuple
    state_space: object
    residual: ResidualSettings


def parse_case_specs(case: Case) -> CaseSpecs:
    """Validate and parse every stage table of ``case`` (ConfigError naming file, table and key)."""
    from livesweep.ident.state_space import StateSpaceModel

    table = case.tables.get("state_space")
    model = StateSpaceModel.from_table(table, where=f"{case.path}: state_space") if table else None
    return CaseSpecs(transfer_function_specs(case), model, residual_settings(case))


@dataclass(frozen=True)
class Identification:
    """Everything one ``identify`` computed for one case.

    Attributes
    ----------
    case : Case
        The parsed case file.
    frequency_response : FrequencyResponseStage
        Records, spectral analysis (``.analysis.best`` is the FrequencyResponseSet the fits use),
        excitation adequacy and the data-quality record.
    transfer_functions : TransferFunctionStage or None
        None when the case has no ``[transfer_functions]`` or ``until`` stopped before it.
    state_space : StateSpaceStage or None
        The case's ``[state_space]`` model fitted, after structure reduction.
    verification : VerificationStage or None
        The fitted model driven open loop on each ``[[verify]]`` record.
    residual : ResidualStage or None
        The residual loop (what the model lacks, the effects added, the final fit).
    specs : CaseSpecs
        The case's stage tables as the stages used them.
    stages : tuple of str
        The stages that ran (names from :data:`STAGES`).
    elapsed_s : float
        Wall time of the stages [s].
    live_models : LiveModels or None
        The models the live monitor recorded (``/livesweep/model``) for the test points inside
        the ``[[identify]]`` records (:mod:`livesweep.stages.live_models`); the report sets them
        beside the transfer functions.
    """

    case: Case
    frequency_response: FrequencyResponseStage
    transfer_functions: TransferFunctionStage | None
    state_space: StateSpaceStage | None
    verification: VerificationStage | None
    residual: ResidualStage | None
    specs: CaseSpecs
    stages: tuple
    elapsed_s: float
    live_models: object = None

    @property
    def responses(self):
        """The frequency responses the fits use (FrequencyResponseSet: conditioned when MISO)."""
        return self.frequency_response.analysis.best

    @property
    def data_quality(self) -> dict:
        """Repairs, wild points, kinematic checks, excitation and notes of every stage (a new dict)."""
        dq = dict(self.frequency_response.data_quality)
        dq["notes"] = [*dq["notes"], *self.notes]
        return dq

    @property
    def notes(self) -> tuple:
        """Notes of the parametric stages (pairs not fitted, logs recovered, fits not converged)."""
        return tuple(n for s in (self.transfer_functions, self.state_space, self.verification) if s is not None
                     for n in s.notes)

    @property
    def model(self):
        """The final state-space model (StateSpaceFit): the residual loop's when it added effects
        (judged on the state-space stage's frequency points, so its J_ave and bounds compare with
        :attr:`model_before_loop`'s), else the state-space stage's; None without a state-space stage."""
        if self.residual is not None and self.residual.final is not None:
            return self.residual.final
        return self.model_before_loop

    @property
    def model_before_loop(self):
        """The state-space stage's fit (after structure reduction), before the residual loop
        added anything; None without a state-space stage."""
        return self.state_space.fit if self.state_space is not None else None


def identify(case: Case | str | Path, *, until: str = "residual-loop",
             progress: Callable[[str], None] | None = None, parallel: bool = True) -> Identification:
    """Run the identify stages of a case file and return what they computed.

    Stages run in the order of :data:`STAGES` up to ``until``; each runs only when the case
    defines it (``[transfer_functions]``, ``[state_space]``, ``[[verify]]``, ``[residual]``
    enabled). The models the live monitor recorded in the logs for the test points inside the
    records (``/livesweep/model``) are read too (``live_models``). Nothing is written to disk.

    Parameters
    ----------
    case : Case, str or Path
        A parsed case or the path of a case file (TOML).
    until : str
        The last stage to run, one of :data:`STAGES`.
    progress : callable, optional
        Called with one line of text as each stage starts.
    parallel : bool
        Fit the transfer functions in a forked child process while this one runs the state-space,
        verification and residual stages (both need only the frequency responses). Used when the
        platform can fork and has a second core; results are the same either way. ``livesweep
        batch`` turns it off (it already runs one case per core).

    Returns
    -------
    Identification

    Raises
    ------
    ConfigError
        A case file, table, key or log that cannot be used (one line naming it), before any
        spectral work when it is in the model tables.
    """
    if until not in STAGES:
        raise ConfigError(f"until = {until!r}: must be one of {', '.join(STAGES)}")
    if not isinstance(case, Case):
        case = load_case(case)
    say = progress if progress is not None else (lambda msg: None)
    specs = parse_case_specs(case)              # bad stage tables fail before any work
    last = STAGES.index(until)
    t0 = time.monotonic()
    say(f"{case.name}: frequency responses from {len(case.identify)} record(s)")
    fr = run_frequency_response_stage(case, parallel=parallel)
    live = read_live_models(case.identify)
    best = fr.analysis.best
    ran = ["frequency-response"]
    tf = ss = ver = res = None
    pending = None
    if last >= 1 and specs.transfer_functions:
        say(f"transfer functions: {', '.join(t.model.name for t in specs.transfer_functions)}")
        overlap = parallel and last >= 2 and specs.state_space is not None
        pending = Background(run_transfer_function_stage, case, best, specs.transfer_functions, fork=overlap)
        if not overlap:
            tf = pending.result()
        ran.append("transfer-functions")
    if last >= 2 and specs.state_space is not None:
        ss = run_state_space_stage(case, best, progress=say, model=specs.state_space)
        ran.append("state-space")
    if last >= 3 and ss is not None and case.verify:
        say(f"verification on {len(case.verify)} record(s)")
        ver = run_verification_stage(case, ss, case.spectral.sample_rate_hz)
        ran.append("verification")
    if last >= 4 and ss is not None:
        say("residual loop: diagnosing what the model lacks")
        res = run_residual_stage(case, best, ss, runner=ver.runner if ver else None, progress=say,
                                 settings=specs.residual)
        if res is not None:
            ran.append("residual-loop")
    if pending is not None:
        tf = pending.result()
    return Identification(case, fr, tf, ss, ver, res, specs, tuple(ran), time.monotonic() - t0, live)

