"""Frequency responses as results: one pair (:class:`FrequencyResponse`) or a MIMO set.

Axis order ``(n_outputs, n_inputs, n_freq)`` (docs/method.md §0). Results keep omega [rad/s], H,
coherence, normalised random error and the settings that produced them; ``to_dict``/``from_dict``
give the JSON form (``report.json`` and later stages).

Arithmetic on pairs (docs/method.md §4.6, §10): product (chain rule), ratio through a common
reference, inverse, and the broken-loop response from closed-loop data. Random errors combine as
``eps^2 = eps_1^2 + eps_2^2`` and coherence as the product (a design choice: CIFER's rule for
derived responses is not public; both make a derived response no better than its parts).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.numeric import frozen_array as _frozen

__all__ = ["FrequencyResponse", "FrequencyResponseSet", "broken_loop"]


def _readonly(a):
    """``a`` as an array the holder cannot write through (a read-only view; no copy)."""
    if a is None:
        return None
    arr = np.asarray(a)
    if arr.flags.writeable:
        arr = arr.view()
        arr.setflags(write=False)
    return arr


def _mag_db(H):
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.abs(H))


def _phase_deg(H):
    """Phase [deg] unwrapped along frequency across the finite points (NaN stays NaN)."""
    H = np.asarray(H)
    out = np.full(H.shape, np.nan)
    ok = np.isfinite(H)
    out[ok] = np.rad2deg(np.unwrap(np.angle(H[ok])))
    return out


def _json_list(x):
    """Floats for JSON: non-finite values become null."""
    return [float(v) if np.isfinite(v) else None for v in np.asarray(x, float)]


@dataclass(frozen=True)
class FrequencyResponse:
    """One input/output pair.

    Attributes
    ----------
    output, input : str
    omega : ndarray
        [rad/s].
    H : ndarray, complex
        Output units per input unit.
    coherence : ndarray
        gamma^2 (partial coherence when ``conditioned``).
    random_error : ndarray
        Normalised random error eps_r (1 sigma, relative).
    conditioned : bool
        True when the other inputs were removed by MISO conditioning.
    """

    output: str
    input: str
    omega: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    random_error: np.ndarray
    conditioned: bool = False

    def __post_init__(self):
        for name in ("omega", "H", "coherence", "random_error"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        n = self.omega.shape
        for name in ("H", "coherence", "random_error"):
            if getattr(self, name).shape != n:
                raise ConfigError(f"FrequencyResponse {self.output}/{self.input}: {name} has shape "
                                  f"{getattr(self, name).shape}, omega {n}")

    def to_frd(self):
        """This response as a SISO ``control.FrequencyResponseData`` (needs python-control).

        See :func:`livesweep.interop.response_to_frd`.
        """
        from livesweep.interop import response_to_frd

        return response_to_frd(self)

    def to_arrays(self) -> dict:
        """Plain, writable copies: ``omega`` [rad/s], ``H`` (complex), ``magnitude_db``,
        ``phase_deg``, ``coherence``, ``random_error``."""
        return {"omega": np.array(self.omega), "H": np.array(self.H), "magnitude_db": np.array(self.magnitude_db),
                "phase_deg": np.array(self.phase_deg), "coherence": np.array(self.coherence),
                "random_error": np.array(self.random_error)}

    @property
    def magnitude_db(self) -> np.ndarray:
        """20 log10 |H| [dB]."""
        return _mag_db(self.H)

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase [deg], unwrapped along frequency."""
        return _phase_deg(self.H)

    def _check_grid(self, other: "FrequencyResponse"):
        if self.omega.shape != other.omega.shape or not np.allclose(self.omega, other.omega, rtol=1e-12):
            raise ConfigError(f"responses {self.output}/{self.input} and {other.output}/{other.input} are on different frequency grids")

    def _combine(self, other, H, output, input):
        self._check_grid(other)
        return FrequencyResponse(output, input, self.omega, H, self.coherence * other.coherence,
                                 np.sqrt(self.random_error**2 + other.random_error**2),
                                 self.conditioned or other.conditioned)

    def __mul__(self, other: "FrequencyResponse") -> "FrequencyResponse":
        """Chain rule: (c/b) * (b/a) = c/a."""
        return self._combine(other, self.H * other.H, self.output, other.input)

    def __truediv__(self, other: "FrequencyResponse") -> "FrequencyResponse":
        """Ratio through a common reference: (y/r) / (u/r) = y/u."""
        return self._combine(other, self.H / other.H, self.output, other.output)

    def inverse(self) -> "FrequencyResponse":
        """x/y from y/x (same coherence and random error)."""
        return FrequencyResponse(self.input, self.output, self.omega, 1.0 / self.H, self.coherence,
                                 self.random_error, self.conditioned)

    def to_dict(self) -> dict:
        """The ``report.json`` form (docs/outputs.md, report.json)."""
        return {
            "output": self.output, "input": self.input,
            "omega_rad_s": self.omega.tolist(),
            "magnitude_db": _json_list(self.magnitude_db),
            "phase_deg": _json_list(self.phase_deg),
            "coherence": _json_list(self.coherence),
            "random_error": _json_list(self.random_error),
            "conditioned": bool(self.conditioned),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "FrequencyResponse":
        mag = np.array([np.nan if v is None else v for v in d["magnitude_db"]], float)
        ph = np.deg2rad(np.array([np.nan if v is None else v for v in d["phase_deg"]], float))
        err = np.array([np.inf if e is None else e for e in d["random_error"]], float)
        return cls(d["output"], d["input"], _frozen(d["omega_rad_s"], float), 10 ** (mag / 20) * np.exp(1j * ph),
                   _frozen(d["coherence"], float), err, bool(d.get("conditioned", False)))


def broken_loop(feedback_over_ref: FrequencyResponse, input_over_ref: FrequencyResponse,
                negative_feedback: bool = True) -> FrequencyResponse:
    """Broken-loop response L = y_fb/u from a closed-loop test with injection r (docs/method.md §10).

    With ``u = r - y_fb`` (negative feedback) ``L = (y_fb/r) / (u/r)``; with an adding junction
    (``u = r + y_fb``) ``L = -(y_fb/r) / (u/r)``.
    """
    L = feedback_over_ref / input_over_ref
    if not negative_feedback:
        L = FrequencyResponse(L.output, L.input, L.omega, -L.H, L.coherence, L.random_error, L.conditioned)
    return L


@dataclass(frozen=True)
class FrequencyResponseSet:
    """Frequency responses of every output to every input on one grid.

    Attributes
    ----------
    outputs, inputs : tuple of str
    omega : ndarray, shape (n_freq,)
        [rad/s], log-spaced over the band.
    H : ndarray, complex, shape (n_out, n_in, n_freq)
    coherence : ndarray, shape (n_out, n_in, n_freq)
        gamma^2; partial coherence when ``conditioned``.
    random_error : ndarray, shape (n_out, n_in, n_freq)
    conditioned : bool
    multiple_coherence : ndarray, shape (n_out, n_freq) or None
    ill_conditioned : ndarray of bool, shape (n_freq,) or None
        Input spectral matrix unreliable (input cross-coherence above the limit).
    settings : dict
        Windows, overlap, sample rate, band, per-window averages, composite method.
    """

    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    omega: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    random_error: np.ndarray
    conditioned: bool = False
    multiple_coherence: np.ndarray | None = None
    ill_conditioned: np.ndarray | None = None
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ("omega", "H", "coherence", "random_error", "multiple_coherence", "ill_conditioned"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        want = (len(self.outputs), len(self.inputs), self.omega.size)
        for name in ("H", "coherence", "random_error"):
            if getattr(self, name).shape != want:
                raise ConfigError(f"FrequencyResponseSet: {name} has shape {getattr(self, name).shape}, "
                                  f"expected (outputs, inputs, frequencies) = {want}")

    def to_frd(self):
        """The set as one MIMO ``control.FrequencyResponseData`` (needs python-control).

        See :func:`livesweep.interop.response_set_to_frd`.
        """
        from livesweep.interop import response_set_to_frd

        return response_set_to_frd(self)

    def pair(self, output: str, input: str) -> FrequencyResponse:
        """One pair; ConfigError naming the pair when it is not in the set."""
        try:
            i, j = self.outputs.index(output), self.inputs.index(input)
        except ValueError:
            raise ConfigError(f"no response {output}/{input}; outputs {self.outputs}, inputs {self.inputs}") from None
        return FrequencyResponse(output, input, self.omega, self.H[i, j], self.coherence[i, j],
                                 self.random_error[i, j], self.conditioned)

    def pairs(self):
        """Every pair, outputs outer, inputs inner."""
        return [self.pair(o, i) for o in self.outputs for i in self.inputs]

    def to_dict(self) -> dict:
        d = {
            "outputs": list(self.outputs), "inputs": list(self.inputs), "conditioned": self.conditioned,
            "omega_rad_s": self.omega.tolist(),
            "H_re": np.where(np.isfinite(self.H), self.H.real, 0.0).tolist(),
            "H_im": np.where(np.isfinite(self.H), self.H.imag, 0.0).tolist(),
            "H_finite": np.isfinite(self.H).tolist(),
            "coherence": self.coherence.tolist(),
            "random_error": np.where(np.isfinite(self.random_error), self.random_error, -1.0).tolist(),
            "settings": self.settings,
        }
        if self.multiple_coherence is not None:
            d["multiple_coherence"] = self.multiple_coherence.tolist()
        if self.ill_conditioned is not None:
            d["ill_conditioned"] = self.ill_conditioned.astype(bool).tolist()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "FrequencyResponseSet":
        err = np.asarray(d["random_error"], float)
        return cls(
            outputs=tuple(d["outputs"]), inputs=tuple(d["inputs"]), omega=np.asarray(d["omega_rad_s"], float),
            H=np.where(np.asarray(d.get("H_finite", True), bool),
                       np.asarray(d["H_re"], float) + 1j * np.asarray(d["H_im"], float), np.nan + 0j),
            coherence=np.asarray(d["coherence"], float), random_error=np.where(err < 0, np.inf, err),
            conditioned=bool(d["conditioned"]),
            multiple_coherence=None if "multiple_coherence" not in d else np.asarray(d["multiple_coherence"], float),
            ill_conditioned=None if "ill_conditioned" not in d else np.asarray(d["ill_conditioned"], bool),
            settings=dict(d.get("settings", {})),
        )
