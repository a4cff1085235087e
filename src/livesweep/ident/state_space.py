"""State-space derivative identification from frequency responses (DERIVID; docs/method.md §8).

Model (docs/method.md §8.1)::

    M x' = F x + G u(t - tau)          y = H x + J u(t - tau)
    T(jw) = [H (jw M - F)^-1 G + J] diag(exp(-jw tau_j))

with M, F, G, H, J given entry by entry as strings of a case's ``[state_space]`` table (numbers,
parameter and constant names, ``+ - * /`` and parentheses; :mod:`livesweep.ident.expression`), one
delay parameter per input (optional). Units are the case file's: states and outputs in whatever
units the matrices imply (the XV-15 cases: v ft/s, p and r rad/s, phi rad; outputs deg/s, deg,
ft/s^2, ft/s), inputs in their signal units (deg), delays in seconds, omega in rad/s.

Cost (docs/method.md §8.2): the NAVFIT cost of every pair the model's outputs and inputs cover, over
that pair's own band at ``N_OMEGA`` = 20 log-spaced points (:mod:`livesweep.ident.cost` -- the one
criterion), summed; ``J_ave = J / n_pairs`` (guideline J_ave <= 100, <= 50 excellent).

Optimiser (docs/method.md §8.3): :func:`scipy.optimize.least_squares` (trust-region reflective) on the
stacked residuals of :func:`livesweep.ident.cost.residuals`, with the exact Jacobian (derivatives
of the matrices' entries times linear solves with ``jw M - F``), Jacobian-based parameter scaling
and delays bounded to ``>= 0``. Accuracy (CR bounds, insensitivities, correlation) comes from the
same Jacobian at the solution (:mod:`livesweep.ident.accuracy`); the structure-reduction loop of
method.md §8.5 is :func:`reduce_structure`.

The work is done in modules with one job each, re-exported here: the table parser
(:mod:`~livesweep.ident.state_space_table`), the model (:mod:`~livesweep.ident.state_space_model`),
the pairs it is fitted to (:mod:`~livesweep.ident.state_space_pairs`), the fit's cost, accuracy and
result (:mod:`~livesweep.ident.state_space_result`), the fit and the structure reduction
(:mod:`~livesweep.ident.state_space_fit`) and the equation-error start
(:mod:`~livesweep.ident.state_space_start`). The refit the residual loop and the coupling search
run, :func:`refit_state_space`, is here.

Examples
--------
>>> from livesweep.ident.state_space import StateSpaceModel
>>> m = StateSpaceModel.from_matrices(states=["p"], inputs=["da"], outputs=["p"],
...                                   F=[["Lp"]], G=[["Lda"]], H=[[1.0]],
...                                   parameters={"Lp": -2.0, "Lda": 5.0})
>>> m.eigenvalues(m.initial)
array([-2.+0.j])
"""

from __future__ import annotations

from livesweep.ident.state_space_fit import MAX_DELTA_COST, fit_state_space, reduce_structure
from livesweep.ident.state_space_model import StateSpaceModel
from livesweep.ident.state_space_pairs import a_priori_eliminations, select_pairs
from livesweep.ident import state_space_result as _result, state_space_table as _table
from livesweep.ident.state_space_result import FittedParameter, StateSpaceFit, evaluate_state_space
from livesweep.ident.state_space_start import equation_error_start

__all__ = ["StateSpaceModel", "FittedParameter", "StateSpaceFit", "select_pairs", "a_priori_eliminations",
           "fit_state_space", "refit_state_space", "evaluate_state_space", "REFIT_NFEV", "reduce_structure", "equation_error_start",
           "MAX_DELTA_COST"]

#: The keys a ``[state_space]`` table may hold (private; docs/case-file.md lists them).
_TABLE_KEYS = _table._TABLE_KEYS
#: Stacked residuals and their exact Jacobian for a model and its pairs (private).
_Problem = _result._Problem

#: Cost evaluations of a refit (the residual loop's, the coupling search's) before it is
#: continued once (:func:`refit_state_space`).
REFIT_NFEV = 100


def refit_state_space(model: StateSpaceModel, pairs) -> StateSpaceFit:
    """A refit of a model changed from a converged one: :func:`fit_state_space` with
    :data:`REFIT_NFEV` cost evaluations; one that budget stopped is continued once from where it
    stopped with twice as many. A slow but steady descent (a delay on a pilot-loop axis, its cost
    equal to 4e-8 after 100 evaluations) is not a failure to converge; a fit still not settled
    after that is reported as one (``converged`` False)."""
    fit = fit_state_space(model, pairs, max_nfev=REFIT_NFEV)
    if not fit.converged:
        more = fit_state_space(fit.model.with_values(fit.theta), pairs, max_nfev=2 * REFIT_NFEV)
        if more.converged or more.cost_average <= fit.cost_average:
            fit = more
    return fit
