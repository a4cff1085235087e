"""Transfer-function models in the factored shorthand of Tischler & Remple's Eq. 2.8, fitted with NAVFIT's cost.

Shorthand (docs/method.md §7.3): ``(1/T)`` means ``(s + 1/T)``, ``[zeta, w]`` means
``(s^2 + 2 zeta w s + w^2)``, ``s`` / ``s^n`` a free differentiator (a root at the origin), the gain K
multiplies the factored form and a delay appears as ``e^(-tau s)``::

    T(s) = K * prod(numerator factors) / prod(denominator factors) * e^(-tau s)

Because every factor is monic, K is the high-frequency gain times s^(relative degree), e.g.
Tischler & Remple's Eq. 2.9 ``p/da = -4.60 s [0.278, 1.93] e^(-0.0533 s) / ((0.0912)(1.00)[0.237, 1.67])``
has ``|p/da| * w -> 4.60`` at high frequency.

Parameters: first-order factors by their inverse time constant ``1/T`` [rad/s] (key ``"1/T"``),
quadratics by damping ``zeta`` [-] and natural frequency ``w`` [rad/s] (keys as written), so the
roots stay real-valued parameters; a negative ``1/T`` or ``zeta`` is an unstable root and is allowed
(``w`` is kept > 0: ``(-zeta, -w)`` is the same quadratic). ``"gain"`` is K (output units per input
unit, times s^(relative degree)) and ``"tau"`` the delay [s], bounded ``0 <= tau <= tau_max_s``.

Fitting (:func:`fit_transfer_function`) minimises the sum of squares of
:func:`livesweep.ident.cost.residuals`, i.e. the cost J of docs/method.md §7.1 summed over the pairs, with
``scipy.optimize.least_squares`` (trust-region reflective, ``x_scale='jac'``, analytic Jacobian of
the model's log-response mapped through the cost's own residual function). Several pairs may be
fitted together with one shared denominator (Tischler & Remple's Eq. 2.7: common lateral-directional
denominator, distinct numerators with their own gain, zeros and delay).

Accuracy (docs/method.md §8.4): the Gauss-Newton Hessian of J is ``H = 2 D^T D`` with ``D = dr/dtheta``
at the solution; ``CR_i = sqrt((H^-1)_ii)`` (absolute, in the parameter's units) and
``CR_i% = 100 CR_i/|theta_i|``; insensitivity ``I_i = 1/sqrt(H_ii)``. **Normalisation.** This is the
CIFER form; it equals the least-squares standard deviation of the estimate only when the residual
variance is 1/2, i.e. when the fit leaves ``J ~ n_omega`` (about 20 per pair). The statistical
(1-sigma) scatter for white fitting-point noise is ``sqrt(2 * residual_variance) * CR_i`` with
``residual_variance = J_total / (N_residuals - n_parameters)`` (reported): with clean data
(J << 20) the CIFER bound is conservative by ``sqrt(1/(2 residual_variance))``.

The work is done in modules with one job each, re-exported here: the shorthand and the model
(:mod:`~livesweep.ident.transfer_function_structure`), the fit's parameter layout and residuals
(:mod:`~livesweep.ident.transfer_function_problem`), the automatic starts
(:mod:`~livesweep.ident.transfer_function_start`), the result
(:mod:`~livesweep.ident.transfer_function_result`) and the fit
(:mod:`~livesweep.ident.transfer_function_fit`).
"""

from __future__ import annotations

from livesweep.ident.transfer_function_fit import fit_transfer_function
from livesweep.ident.transfer_function_result import FittedTransferFunction
from livesweep.ident.transfer_function_structure import (RESERVED_NAMES, STRUCTURE_PREFIXES, Factor, Structure,
                                                         TransferFunctionModel, parse_structure)

__all__ = ["Factor", "Structure", "parse_structure", "TransferFunctionModel", "FittedTransferFunction",
           "fit_transfer_function", "RESERVED_NAMES", "STRUCTURE_PREFIXES"]
