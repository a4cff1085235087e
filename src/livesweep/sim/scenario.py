"""A simulated test point: vehicle model, manoeuvres, effects, sensors, turbulence, pilot.

``simulate(scenario)`` runs it and returns a :class:`SimResult` with the logged control
commands and the sensor measurements, each at its own rate on the vehicle clock, plus the
noise-free histories on the fine grid (for tests) and a record of what was injected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from livesweep.errors import ConfigError
from livesweep.sim.effects import Dropouts, Effect, ScaleFactor, SensorBias, SensorSkew, Spikes
from livesweep.sim.engine import PilotLoop, Turbulence, augment, shift, step
from livesweep.sim.inputs import FrequencySweep, Multistep, PilotNoise, Step, Trim
from livesweep.sim.models import LinearVehicleModel, get_model

__all__ = [
    "Sensor",
    "Segment",
    "Scenario",
    "SampledSignal",
    "SegmentTimes",
    "SimResult",
    "simulate",
    "default_sensors",
    "default_turbulence",
    "default_pilot",
    "VehicleDefaults",
    "VEHICLE_DEFAULTS",
    "sweep_scenario",
    "verification_scenario",
]


@dataclass(frozen=True)
class Sensor:
    """A sensor: which output it measures, at what rate [Hz] and with what white noise (1 sigma, output units)."""

    output: str
    rate_hz: float
    noise_std: float = 0.0


@dataclass(frozen=True)
class Segment:
    """One manoeuvre of a test point.

    Parameters
    ----------
    label : str
        Words for the flight-test card, e.g. ``"aileron sweep 1"``.
    kind : str
        ``sweep``, ``doublet``, ``3211``, ``step``, ``multistep`` or ``trim``.
    axis : str or None
        The input the manoeuvre excites.
    signal : callable
        The on-axis signal (``livesweep.sim.inputs``); its ``total_duration_s`` sets the length.
    off_axis : tuple of (str, callable)
        Other inputs' signals during the segment (e.g. small pilot noise).
    """

    label: str
    kind: str
    axis: str | None
    signal: object
    off_axis: tuple = ()

    @property
    def duration_s(self) -> float:
        return float(self.signal.total_duration_s)


@dataclass(frozen=True)
class Scenario:
    """Everything that defines a simulated test point (deterministic for a given ``seed``).

    Parameters
    ----------
    model : LinearVehicleModel
    segments : tuple of Segment
        Flown back to back.
    effects : tuple of Effect
    sensors : tuple of Sensor
        One per measured output; rates must divide ``internal_rate_hz``.
    input_rate_hz : float
        Rate at which the control commands are logged [Hz].
    turbulence : Turbulence or None
    pilot : PilotLoop or None
    internal_rate_hz : float
        Simulation grid rate [Hz].
    seed : int
    boot_time_s : float
        Vehicle clock at the start of the first segment [s since boot].
    condition : str
        Flight condition in words (for the log's test-point metadata).
    """

    model: LinearVehicleModel
    segments: tuple[Segment, ...]
    effects: tuple[Effect, ...] = ()
    sensors: tuple[Sensor, ...] = ()
    input_rate_hz: float = 50.0
    turbulence: Turbulence | None = None
    pilot: PilotLoop | None = None
    internal_rate_hz: float = 400.0
    seed: int = 0
    boot_time_s: float = 100.0
    condition: str = ""

    def __post_init__(self):
        if not self.segments:
            raise ConfigError("a scenario needs at least one manoeuvre segment")
        fs = float(self.internal_rate_hz)
        if not math.isfinite(fs) or fs <= 0:
            raise ConfigError(f"internal_rate_hz must be > 0, got {self.internal_rate_hz!r}")
        for name, rate in [("input_rate_hz", self.input_rate_hz)] + [
            (f"sensor {s.output} rate_hz", s.rate_hz) for s in self.sensors
        ]:
            ratio = fs / float(rate) if rate and rate > 0 else float("nan")
            if not math.isfinite(ratio) or abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
                raise ConfigError(f"{name} = {rate!r} must divide internal_rate_hz = {fs:g}")
        for seg in self.segments:
            if seg.axis is not None:
                self.model.input_index(seg.axis)
            for name, _ in seg.off_axis:
                self.model.input_index(name)
        for s in self.sensors:
            self.model.output_index(s.output)
            if not math.isfinite(s.noise_std) or s.noise_std < 0:
                raise ConfigError(f"sensor {s.output} noise_std must be >= 0, got {s.noise_std!r}")
        for e in self.effects:
            if e.acts_on == "input":
                self.model.input_index(e.input)
            else:
                self.model.output_index(e.output)
                if e.output not in {s.output for s in self.sensors}:
                    raise ConfigError(f"effect {e.kind} targets output {e.output!r}, which no sensor measures")

    @property
    def duration_s(self) -> float:
        """Total length of the test point [s]."""
        return sum(seg.duration_s for seg in self.segments)


@dataclass(frozen=True)
class SampledSignal:
    """One signal as a sensor or the control system delivers it.

    ``t_s`` is the vehicle time stamp [s since boot]; ``values`` are in ``units`` and are NaN
    where a dropout removed the sample (``valid`` is False there).
    """

    name: str
    units: str
    t_s: np.ndarray
    values: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.values)

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t_s)))


@dataclass(frozen=True)
class SegmentTimes:
    """Where a segment sits on the vehicle clock [s since boot]."""

    label: str
    kind: str
    axis: str | None
    start_s: float
    end_s: float
    parameters: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SimResult:
    """What :func:`simulate` returns.

    Attributes
    ----------
    scenario : Scenario
    inputs : dict of str -> SampledSignal
        Logged control commands at ``scenario.input_rate_hz`` (with the pilot loop's feedback).
    injections : dict of str -> SampledSignal
        The exogenous part of each command (sweeps, doublets, off-axis noise: everything but the
        pilot loop's feedback) at ``scenario.input_rate_hz``; equal to ``inputs`` without a pilot.
    outputs : dict of str -> SampledSignal
        Sensor measurements with every effect, noise included.
    segments : tuple of SegmentTimes
    t_fine_s : ndarray
        Fine grid [s since boot].
    u_fine : ndarray, shape (N, n_in)
        Logged command on the fine grid.
    y_fine : ndarray, shape (N, n_out)
        Outputs after dynamic effects, before sensor effects and noise.
    injected : dict
        What random effects did: spike sample indices and dropout intervals per output.
    """

    scenario: Scenario
    inputs: dict
    injections: dict
    outputs: dict
    segments: tuple
    t_fine_s: np.ndarray
    u_fine: np.ndarray
    y_fine: np.ndarray
    injected: dict


def _rngs(seed: int, n: int):
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n)]


def simulate(scenario: Scenario) -> SimResult:
    """Fly the test point.

    Parameters
    ----------
    scenario : Scenario

    Returns
    -------
    SimResult
    """
    model = scenario.model
    fs = float(scenario.internal_rate_hz)
    dt = 1.0 / fs
    seg_samples = [int(round(seg.duration_s * fs)) for seg in scenario.segments]
    N = sum(seg_samples) + 1
    t_rel = np.arange(N) * dt
    u_cmd = np.zeros((N, len(model.inputs)))
    seg_times = []
    k0 = 0
    for seg, n in zip(scenario.segments, seg_samples):
        sl = slice(k0, k0 + n + 1)
        t_local = t_rel[sl] - t_rel[k0]
        if seg.axis is not None:
            u_cmd[sl, model.input_index(seg.axis)] += seg.signal(t_local)
        for name, sig in seg.off_axis:
            u_cmd[sl, model.input_index(name)] += sig(t_local)
        params = {k: v for k, v in vars(seg.signal).items() if isinstance(v, (int, float, tuple))}
        seg_times.append(SegmentTimes(seg.label, seg.kind, seg.axis, scenario.boot_time_s + k0 * dt,
                                      scenario.boot_time_s + (k0 + n) * dt, params))
        k0 += n

    rng_turb, rng_noise, rng_spikes, rng_drop = _rngs(scenario.seed, 4)
    system = augment(model, list(scenario.effects), scenario.turbulence)
    eta = rng_turb.standard_normal((N, system.Bw.shape[1])) / math.sqrt(dt)
    u_log, y_dyn = step(system, dt, u_cmd, eta, scenario.pilot)
    if not (np.all(np.isfinite(y_dyn)) and np.max(np.abs(y_dyn)) < 1e6):
        raise ConfigError(
            f"the simulation of {model.name!r} diverged; an unstable model needs a stabilising pilot loop"
        )
    t_vehicle = scenario.boot_time_s + t_rel

    inputs, injections = {}, {}
    step_in = int(round(fs / scenario.input_rate_hz))
    for i, name in enumerate(model.inputs):
        t_in = t_vehicle[::step_in].copy()
        inputs[name] = SampledSignal(name, model.input_units[i], t_in, u_log[::step_in, i].copy())
        injections[name] = SampledSignal(name, model.input_units[i], t_in.copy(), u_cmd[::step_in, i].copy())

    outputs, injected = {}, {"spikes": {}, "dropouts": {}}
    out_rngs = {s.output: r for s, r in zip(scenario.sensors, rng_noise.spawn(len(scenario.sensors)))}
    for s in scenario.sensors:
        j = model.output_index(s.output)
        k_step = int(round(fs / s.rate_hz))
        effs = [e for e in scenario.effects if e.acts_on == "output" and e.output == s.output]
        skew = sum(e.delay_s for e in effs if isinstance(e, SensorSkew))
        y = shift(y_dyn[:, j], skew * fs) if skew else y_dyn[:, j]
        y = y[::k_step].copy()
        t = t_vehicle[::k_step].copy()
        for e in effs:
            if isinstance(e, ScaleFactor):
                y *= e.factor
        for e in effs:
            if isinstance(e, SensorBias):
                y += e.bias
        if s.noise_std > 0:
            y += s.noise_std * out_rngs[s.output].standard_normal(y.size)
        for e in effs:
            if isinstance(e, Spikes):
                n_sp = rng_spikes.poisson(e.rate_hz * (t[-1] - t[0]))
                idx = np.sort(rng_spikes.choice(y.size, size=min(n_sp, y.size), replace=False))
                y[idx] += e.magnitude * rng_spikes.choice([-1.0, 1.0], size=idx.size)
                injected["spikes"].setdefault(s.output, []).extend(idx.tolist())
        for e in effs:
            if isinstance(e, Dropouts):
                starts = np.sort(rng_drop.uniform(t[0], max(t[0], t[-1] - e.duration_s), size=e.count))
                for a in starts:
                    y[(t >= a) & (t < a + e.duration_s)] = np.nan
                    injected["dropouts"].setdefault(s.output, []).append((float(a), float(a + e.duration_s)))
        outputs[s.output] = SampledSignal(s.output, model.output_units[j], t, y)

    return SimResult(
        scenario=scenario, inputs=inputs, injections=injections, outputs=outputs, segments=tuple(seg_times),
        t_fine_s=t_vehicle, u_fine=u_log, y_fine=y_dyn, injected=injected,
    )


# --- standard test points -------------------------------------------------------------------

_SENSOR_DEFAULTS = {
    # output: (rate Hz, noise 1-sigma in output units)
    "p": (100.0, 0.05),     # deg/s
    "r": (100.0, 0.05),     # deg/s
    "ay": (100.0, 0.05),    # ft/s^2
    "beta": (50.0, 0.1),    # deg (vane)
    "v": (50.0, 0.1),       # ft/s (reconstructed)
    "phi": (50.0, 0.05),    # deg
}


@dataclass(frozen=True)
class VehicleDefaults:
    """A model's own standard test-point settings (models without an entry use the XV-15's).

    Parameters
    ----------
    sensors : dict of str -> (float, float)
        Output -> (rate [Hz], white-noise 1 sigma [output units]).
    turbulence : Turbulence
        Light turbulence on the model's gusts.
    pilot : PilotLoop or None
        The stabilising loop the test points are flown with.
    input_rate_hz : float
        Rate at which the commands are logged [Hz].
    internal_rate_hz : float
        Simulation grid [Hz]; every rate above divides it.
    """

    sensors: dict
    turbulence: Turbulence
    pilot: PilotLoop | None
    input_rate_hz: float = 50.0
    internal_rate_hz: float = 400.0


#: Per-model defaults, by model name.
VEHICLE_DEFAULTS = {
    # Quadrotor: IMU (gyros, accelerometers) and the commands logged at the 400 Hz rate-loop rate,
    # attitude estimate at 200 Hz (PX4 logs vehicle_attitude at 200-250 Hz). Noise: a MEMS gyro's
    # ~0.007 deg/s/sqrt(Hz) over 200 Hz, with vibration, 0.1 deg/s; accelerometers 0.1 m/s^2
    # (vibration after the autopilot's low-pass filter); estimator attitude 0.05 deg.
    # Turbulence: 0.5 m/s gusts with a 2 s correlation time (light air near the ground).
    # Pilot: the autopilot's attitude hold, roll_cmd = -0.008 phi - 0.002 p (per deg, per deg/s),
    # pitch alike, 5 ms loop latency: about 4.5 rad/s crossover, 80 deg phase and 23 dB gain
    # margin with the 20 ms motor delay; slowest closed-loop pole -0.9 rad/s.
    "quad-attitude": VehicleDefaults(
        sensors={"p": (400.0, 0.1), "q": (400.0, 0.1), "ax": (400.0, 0.1), "ay": (400.0, 0.1),
                 "phi": (200.0, 0.05), "theta": (200.0, 0.05)},
        turbulence=Turbulence(sigmas=(0.5, 0.5), correlation_time_s=2.0),
        pilot=PilotLoop(gains=(("roll_cmd", "phi", -0.008), ("roll_cmd", "p", -0.002),
                               ("pitch_cmd", "theta", -0.008), ("pitch_cmd", "q", -0.002)), delay_s=0.005),
        input_rate_hz=400.0,
        internal_rate_hz=400.0,
    ),
}


def default_sensors(model: LinearVehicleModel, noise: bool = True) -> tuple[Sensor, ...]:
    """One sensor per model output at a realistic rate, with (or without) white noise."""
    own = VEHICLE_DEFAULTS.get(model.name)
    table = own.sensors if own is not None else _SENSOR_DEFAULTS
    for o in model.outputs:
        if o not in table:
            raise ConfigError(f"no default sensor for output {o!r} of model {model.name!r}; give sensors explicitly")
    return tuple(Sensor(o, table[o][0], table[o][1] if noise else 0.0) for o in model.outputs)


def default_turbulence(model: LinearVehicleModel) -> Turbulence:
    """Light turbulence: cruise sigma_v 3 ft/s, sigma_p 0.02 rad/s, T 4 s; hover 1.5 ft/s, 0.02 rad/s, 3 s.

    Models in :data:`VEHICLE_DEFAULTS` use their own (the quadrotor: 0.5 m/s on u_g and v_g, 2 s).
    """
    own = VEHICLE_DEFAULTS.get(model.name)
    if own is not None:
        return own.turbulence
    if model.constants.get("U0_ft_s", 0.0) > 0:
        return Turbulence(sigmas=(3.0, 0.02), correlation_time_s=4.0)
    return Turbulence(sigmas=(1.5, 0.02), correlation_time_s=3.0)


def default_pilot(model: LinearVehicleModel) -> PilotLoop | None:
    """A stabilising pilot for models with an unstable mode, else None.

    For the XV-15 in hover: aileron = 0.5 phi + 0.2 p and rudder = -1.0 r (deg per deg and
    per deg/s), 0.2 s reaction delay; the closed loop's slowest pole is then -0.18 rad/s.
    Models in :data:`VEHICLE_DEFAULTS` use their own loop (the quadrotor: its autopilot's
    attitude hold).
    """
    own = VEHICLE_DEFAULTS.get(model.name)
    if own is not None:
        return own.pilot
    if np.all(model.eigenvalues().real < 0):
        return None
    return PilotLoop(gains=(("da", "phi", 0.5), ("da", "p", 0.2), ("dr", "r", -1.0)), delay_s=0.2)


def _rates(m: LinearVehicleModel) -> dict:
    """``input_rate_hz`` and ``internal_rate_hz`` of the model's standard test points [Hz]."""
    own = VEHICLE_DEFAULTS.get(m.name)
    if own is None:
        return {}
    return {"input_rate_hz": own.input_rate_hz, "internal_rate_hz": own.internal_rate_hz}


def _standard_scenario(m, segments, effects, noise, turbulence, seed, turbulence_scale: float = 1.0) -> Scenario:
    """A test point with the model's default sensors, turbulence (scaled), (if unstable) pilot and rates."""
    turb = None
    if turbulence:
        d = default_turbulence(m)
        turb = Turbulence(sigmas=tuple(turbulence_scale * s for s in d.sigmas), correlation_time_s=d.correlation_time_s)
    return Scenario(
        model=m,
        segments=tuple(segments),
        effects=tuple(effects),
        sensors=default_sensors(m, noise),
        turbulence=turb,
        pilot=default_pilot(m),
        seed=seed,
        condition=m.description,
        **_rates(m),
    )


def sweep_scenario(
    model: str | LinearVehicleModel = "xv15-cruise",
    axes: tuple[str, ...] = ("da",),
    repeats: int = 2,
    omega_min_rad_s: float = 0.3,
    omega_max_rad_s: float = 20.0,
    duration_s: float = 100.0,
    amplitudes: dict | None = None,
    off_axis_rms: float = 0.0,
    effects: tuple[Effect, ...] = (),
    noise: bool = True,
    turbulence: bool = True,
    seed: int = 0,
    trim_s: float = 3.0,
    lead_in_s: float = 5.0,
    turbulence_scale: float = 1.0,
) -> Scenario:
    """``repeats`` computer-generated sweeps per axis, flown one after another.

    Parameters
    ----------
    model : str or LinearVehicleModel
    axes : tuple of str
        Inputs to sweep, in order.
    repeats : int
        Sweeps per axis (Tischler & Remple concatenate two).
    omega_min_rad_s, omega_max_rad_s, duration_s : float
        Sweep band [rad/s] and length [s] (see :class:`FrequencySweep`).
    amplitudes : dict of str -> float
        Sweep amplitude per axis (input units); default 1 for any axis not given.
    off_axis_rms : float
        RMS of a small uncorrelated pilot noise on the other inputs (0 = none).
    effects : tuple of Effect
    noise, turbulence : bool
        Sensor noise and turbulence on or off.
    seed : int
    trim_s : float
        Trim before and after each sweep [s].
    lead_in_s : float
        Trim at the very start [s].
    turbulence_scale : float
        Multiplies the default turbulence.
    """
    m = get_model(model) if isinstance(model, str) else model
    if int(repeats) != repeats or repeats < 1:
        raise ConfigError(f"repeats must be a whole number >= 1, got {repeats!r}")
    amplitudes = dict(amplitudes or {})
    segments = [Segment("trim", "trim", None, Trim(lead_in_s))]
    for a_i, axis in enumerate(axes):
        m.input_index(axis)
        for r in range(int(repeats)):
            sw = FrequencySweep(omega_min_rad_s, omega_max_rad_s, duration_s, amplitudes.get(axis, 1.0), trim_s=trim_s)
            off = ()
            if off_axis_rms > 0:
                off = tuple(
                    (other, PilotNoise(off_axis_rms, 1.0, seed=seed * 1000 + a_i * 100 + r * 10 + k))
                    for k, other in enumerate(m.inputs) if other != axis
                )
            segments.append(Segment(f"{axis} sweep {r + 1}", "sweep", axis, sw, off))
    return _standard_scenario(m, segments, effects, noise, turbulence, seed, turbulence_scale)


def verification_scenario(
    model: str | LinearVehicleModel = "xv15-cruise",
    manoeuvres: tuple[tuple[str, str, float, float], ...] = (("da", "doublet", 2.0, 1.0), ("dr", "doublet", 3.0, 1.5)),
    effects: tuple[Effect, ...] = (),
    noise: bool = True,
    turbulence: bool = True,
    seed: int = 0,
    turbulence_scale: float = 1.0,
) -> Scenario:
    """Dissimilar manoeuvres for time-domain verification.

    Parameters
    ----------
    turbulence_scale : float
        Multiplies the default turbulence (verification is flown in calm air: 0.3).
    manoeuvres : tuple of (axis, kind, amplitude, unit_s)
        ``kind`` is ``doublet``, ``3211`` or ``step``; ``unit_s`` is the pulse (or hold) length [s].
    """
    m = get_model(model) if isinstance(model, str) else model
    segments = [Segment("trim", "trim", None, Trim(5.0))]
    for axis, kind, amp, unit in manoeuvres:
        m.input_index(axis)
        if kind == "doublet":
            sig = Multistep(amp, unit, (1, 1), trim_s=2.0, settle_s=12.0)
        elif kind == "3211":
            sig = Multistep(amp, unit, (3, 2, 1, 1), trim_s=2.0, settle_s=12.0)
        elif kind == "step":
            sig = Step(amp, unit, trim_s=2.0, settle_s=8.0)
        else:
            raise ConfigError(f"unknown verification manoeuvre {kind!r}; use doublet, 3211 or step")
        segments.append(Segment(f"{axis} {kind}", kind, axis, sig))
    return _standard_scenario(m, segments, effects, noise, turbulence, seed, turbulence_scale)
