"""The sample logs shipped in ``replay_logs/``: their scenarios, defined once.

``replay_logs/regenerate.py`` writes them; the tests regenerate them and compare hashes.
Each log stays under 5 MB, so each sweep axis gets its own log (two sweeps per axis, as in
Tischler & Remple's Fig. 2.4).
"""

from __future__ import annotations

from livesweep.sim.scenario import Scenario, sweep_scenario, verification_scenario

__all__ = ["SAMPLE_LOGS", "sample_scenario"]

#: file name -> (description, builder)
SAMPLE_LOGS = {
    "xv15_cruise_sweeps_da.mcap": (
        "XV-15 cruise 170 kn: two aileron sweeps 0.3-20 rad/s, 100 s each, +/-3 deg, light turbulence",
        lambda: sweep_scenario("xv15-cruise", axes=("da",), repeats=2, omega_min_rad_s=0.3, omega_max_rad_s=20.0,
                               duration_s=100.0, amplitudes={"da": 3.0}, off_axis_rms=0.2, seed=11),
    ),
    "xv15_cruise_sweeps_dr.mcap": (
        "XV-15 cruise 170 kn: two rudder sweeps 0.3-20 rad/s, 100 s each, +/-5 deg, light turbulence",
        lambda: sweep_scenario("xv15-cruise", axes=("dr",), repeats=2, omega_min_rad_s=0.3, omega_max_rad_s=20.0,
                               duration_s=100.0, amplitudes={"dr": 5.0}, off_axis_rms=0.2, seed=12),
    ),
    "xv15_cruise_verify.mcap": (
        "XV-15 cruise 170 kn, calm air (30 % of the sweeps' turbulence): aileron doublet, rudder doublet, "
        "aileron 3-2-1-1 (verification)",
        lambda: verification_scenario("xv15-cruise", manoeuvres=(("da", "doublet", 2.0, 1.0),
                                                                 ("dr", "doublet", 3.0, 1.5),
                                                                 ("da", "3211", 1.5, 0.7)), seed=13,
                                      turbulence_scale=0.3),
    ),
    "xv15_hover_sweeps_da.mcap": (
        "XV-15 hover, SCAS off, pilot stabilising, calm air (30 % turbulence), sweep injection logged: "
        "two aileron sweeps 0.2-12 rad/s, 100 s each, +/-1.5 deg",
        lambda: sweep_scenario("xv15-hover", axes=("da",), repeats=2, omega_min_rad_s=0.2, omega_max_rad_s=12.0,
                               duration_s=100.0, amplitudes={"da": 1.5}, off_axis_rms=0.2, seed=21,
                               turbulence_scale=0.3),
    ),
    "xv15_hover_sweeps_dr.mcap": (
        "XV-15 hover, SCAS off, pilot stabilising, calm air (30 % turbulence), sweep injection logged: "
        "two rudder sweeps 0.2-12 rad/s, 100 s each, +/-3 deg",
        lambda: sweep_scenario("xv15-hover", axes=("dr",), repeats=2, omega_min_rad_s=0.2, omega_max_rad_s=12.0,
                               duration_s=100.0, amplitudes={"dr": 3.0}, off_axis_rms=0.2, seed=22,
                               turbulence_scale=0.3),
    ),
}


def sample_scenario(name: str) -> Scenario:
    """Scenario of the sample log ``name`` (a key of :data:`SAMPLE_LOGS`)."""
    return SAMPLE_LOGS[name][1]()
