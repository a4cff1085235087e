"""livesweep in a notebook: arrays in, python-control out.

1. frequency response of a simulated roll axis from numpy arrays;
2. a transfer-function fit, handed to python-control (``to_tf``) and compared with the data
   (``to_frd``) on a Bode plot;
3. ``identify()`` of the shipped XV-15 cruise case and its state-space model as a python-control
   ``StateSpace`` (``to_ss``).

Run from the repository's root (needs python-control: pip install 'livesweep[control]'):

    python examples/notebook_arrays.py [--plot FILE.png]
"""

import argparse
from pathlib import Path

import control
import numpy as np
import scipy.signal

import livesweep

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot", help="write the Bode comparison to this PNG")
    args = ap.parse_args(argv)

    # 1. data: p/da = 4 (s + 0.5) / (s^2 + 2 0.5 6 s + 36) with a 40 ms delay, 50 Hz, noisy sweep
    rate, tau = 50.0, 0.04
    truth = control.tf([4.0, 2.0], [1.0, 6.0, 36.0])
    t = np.arange(0.0, 240.0, 1 / rate)
    rng = np.random.default_rng(1)
    da = scipy.signal.chirp(t, 0.05, t[-1], 4.0, method="logarithmic") + 0.3 * rng.standard_normal(t.size)
    shift = int(round(tau * rate))
    p = control.forced_response(truth, t, np.concatenate([np.zeros(shift), da[:-shift]])).outputs
    p = p + 0.02 * rng.standard_normal(t.size)
    frs = livesweep.frequency_response(da, p, sample_rate_hz=rate, band_rad_s=(0.5, 25.0),
                                       input_names="da", output_names="p")
    data = frs.pair("p", "da")
    print(f"frequency response p/da: {data.omega.size} points, {data.omega[0]:.2f}-{data.omega[-1]:.1f} rad/s, "
          f"median coherence {np.median(data.coherence):.3f}")

    # 2. fit and python-control
    fit = livesweep.fit_transfer_function(data, numerator="(1/T)", denominator="[zeta, w]")
    print(f"fit: gain {fit.gain:.3f}, zero {fit.zeros.real[0]:.3f} rad/s, poles {np.round(fit.poles, 3)}, "
          f"delay {1000 * fit.delay_s:.1f} ms, J {fit.cost:.2f}")
    T = fit.to_tf()                      # the rational part; the delay is fit.delay_s
    frd = data.to_frd()
    w = frd.omega
    model = control.frequency_response(T, w).complex * np.exp(-1j * w * fit.delay_s)
    print(f"largest |fit - data| / |data|: {np.max(np.abs(model - frd.complex.ravel()) / np.abs(frd.complex.ravel())):.3f}")
    if args.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        control.bode_plot([frd, control.series(control.tf(*control.pade(fit.delay_s, 6)), T)], w,
                          label=["data (to_frd)", "fit (to_tf, Pade delay)"], title="p/da: data and fit")
        plt.savefig(args.plot, dpi=80)
        print(f"wrote {args.plot}")

    # 3. a shipped case, identified, as a python-control StateSpace
    ident = livesweep.identify(ROOT / "config" / "xv15_cruise_lateral.toml", until="state-space")
    fit_ss = ident.state_space.fit
    sys = fit_ss.to_ss()
    print(f"identify: {ident.case.name}, stages {', '.join(ident.stages)}, J_ave {fit_ss.cost_average:.2f}")
    print(f"to_ss: {sys.nstates} states {list(fit_ss.model.states)}, poles {np.round(control.poles(sys), 3)}")
    return {"fit": fit, "data": data, "tf": T, "frd": frd, "ident": ident, "ss": sys}


if __name__ == "__main__":
    main()
