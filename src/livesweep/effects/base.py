"""What every effect kind is: its parameters, its frequency response, how the residual loop finds
it and how it is added to a model (:mod:`livesweep.effects`)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from livesweep.errors import require_number

__all__ = ["Effect", "Candidate", "ParameterRole", "ROLES", "check_number"]

#: What a parameter an effect adds to a model does: places it in frequency [rad/s], shapes it
#: (a damping, a notch's depth) [-], delays [s], or scales [-].
ROLES = ("frequency", "damping", "shape", "delay", "gain")


def check_number(kind, name, value, *, positive=False, nonneg=False, upper=None) -> float:
    """``value`` as a finite float, or ConfigError naming the effect and the parameter."""
    return require_number(value, f"effect {kind}: {name}", positive=positive, nonnegative=nonneg, upper=upper)


@dataclass(frozen=True)
class ParameterRole:
    """A model parameter an effect adds: named ``f"{stem}_{where}"`` (``w_notch_da``), with its
    role (one of :data:`ROLES`) and units. The report's units, the residual loop's choice of
    what may be fixed and its band check read these, never the parameter's name."""

    stem: str
    role: str
    unit: str

    def __post_init__(self):
        if self.role not in ROLES:
            raise ValueError(f"parameter {self.stem}: role {self.role!r} is not one of {', '.join(ROLES)}")

    def name(self, where: str) -> str:
        """The parameter's name at ``where`` (an input or output)."""
        return f"{self.stem}_{where}"


@dataclass(frozen=True)
class Candidate:
    """A ranked explanation of a model's residual: an effect kind at a place.

    Attributes
    ----------
    kind : str
        An effect kind of the catalogue (:data:`livesweep.effects.EFFECT_KINDS`).
    where : str
        Input or output name, or for ``missing_derivative`` the parameter (an existing fixed
        one, or the new entry as ``"F[r][p]"``).
    parameters : dict
        Screening estimates, named as the effect's own parameters (s, rad/s, -).
    evidence : float
        Whitened sum-of-squares drop (noise units), after the model's own parameters re-adjust.
    n_parameters : int
        Parameters the effect adds to the model (what a selection criterion counts).
    sensitivity : float or None
        For an effect whose signature is fixed up to its amplitude ``a`` (a scale factor's
        ``ln factor``): the evidence per ``a**2`` left after the model's own parameters absorb
        what they can. ``sqrt(needed / sensitivity)`` is the smallest amplitude the data could
        show; None for other kinds.
    """

    kind: str
    where: str
    parameters: dict
    evidence: float
    n_parameters: int = 1
    sensitivity: float | None = None

    def to_dict(self) -> dict:
        return {"kind": self.kind, "where": self.where, "evidence": round(float(self.evidence), 2),
                "n_parameters": self.n_parameters,
                **({"sensitivity": round(self.sensitivity, 4)} if self.sensitivity is not None else {}),
                "parameters": {k: (round(float(v), 6) if isinstance(v, float) else v) for k, v in self.parameters.items()}}


class Effect:
    """Base of all effect kinds. One subclass per kind holds everything about it.

    Class attributes
    ----------------
    kind : str
        Its name in case files, logs and reports.
    acts_on : str
        ``"input"`` (between the logged command and the vehicle), ``"output"`` (between the
        vehicle and the logged measurement) or ``"entry"`` (a model parameter).
    linear : bool
        Whether it is an LTI factor (:meth:`frequency_response`).
    dynamics : str or None
        How the simulator realises it: ``"delay"``, ``"input_block"``/``"output_block"`` (a
        state-space block from :meth:`state_space`) or None (applied at sampling, or not simulated).
    searched : bool
        Whether the residual loop looks for it (:meth:`candidates`, :meth:`augment`).
    places : tuple of str
        Where the residual loop looks: ``"input"``, ``"output"`` or both.
    n_parameters : int
        Parameters it adds to a model.
    parameter_roles : tuple of ParameterRole
        Every parameter it adds to a model (:meth:`parameter_name` names them).
    """

    kind: ClassVar[str]
    acts_on: ClassVar[str]
    linear: ClassVar[bool] = True
    dynamics: ClassVar[str | None] = None
    searched: ClassVar[bool] = False
    places: ClassVar[tuple] = ()
    n_parameters: ClassVar[int] = 0
    parameter_roles: ClassVar[tuple] = ()

    @classmethod
    def parameter_name(cls, stem: str, where: str) -> str:
        """The name of the declared parameter ``stem`` at ``where``; KeyError for an undeclared one
        (every parameter an effect adds has a role and units)."""
        for r in cls.parameter_roles:
            if r.stem == stem:
                return r.name(where)
        raise KeyError(f"effect {cls.kind}: parameter {stem!r} is not among its parameter_roles")

    @property
    def target(self) -> str:
        return getattr(self, self.acts_on)

    def frequency_response(self, omega_rad_s) -> np.ndarray:
        """Complex factor the effect applies at ``omega_rad_s`` [rad/s] (1 where it has none)."""
        return np.ones(np.shape(omega_rad_s), dtype=complex)

    def as_dict(self) -> dict:
        """``{"kind": ..., <parameters>}``, the form written to logs and reports."""
        return {"kind": self.kind, **{f.name: getattr(self, f.name) for f in fields(self)}}

    # -- the residual loop ------------------------------------------------------------------------

    @classmethod
    def screen(cls, space, place: str, select) -> tuple[dict, float] | None:
        """Best screening parameters and evidence at one place, or None when it does not apply.

        ``space`` is the residual space (:class:`livesweep.ident.residual_space.ResidualSpace`),
        ``select(pair) -> bool`` picks the pairs the place affects.
        """
        return None

    @classmethod
    def candidates(cls, space, table: dict) -> list[Candidate]:
        """Every place's best candidate (:meth:`screen` on each input and/or output)."""
        out = []
        for side in cls.places:
            names = space.model.inputs if side == "input" else space.model.outputs
            for name in names:
                sel = (lambda p, n=name: p.input == n) if side == "input" else (lambda p, n=name: p.output == n)
                got = cls.screen(space, name, sel)
                if got is not None:
                    out.append(Candidate(cls.kind, name, got[0], float(got[1]), cls.n_parameters,
                                         cls.sensitivity(space, name, sel)))
        return out

    @classmethod
    def sensitivity(cls, space, place: str, select) -> float | None:
        """For a signature fixed up to its amplitude: evidence per squared amplitude after the
        model's parameters absorb their share (:attr:`Candidate.sensitivity`); None otherwise."""
        return None

    @classmethod
    def augment(cls, table: dict, where: str, parameters: dict) -> tuple[dict, list[str]]:
        """Add the effect to a normalised ``[state_space]`` table in place; the new parameter names."""
        raise NotImplementedError(f"the residual loop cannot add {cls.kind}")
