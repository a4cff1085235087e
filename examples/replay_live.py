"""The live pipeline on a recorded log: what ``livesweep replay`` does, from Python.

A recorded MCAP log goes through the same aligner, sliding-window estimator and verdict as live
telemetry; the example prints the final coherence of each pair and the verdict.

    python examples/replay_live.py [LOG.mcap]

Default: the shipped XV-15 cruise aileron sweeps, with the packaged XV-15 channel map.
"""

import argparse
from pathlib import Path

import numpy as np

from livesweep.config import read_channel_map
from livesweep.monitor.pipeline import MonitorPipeline, MonitorSettings
from livesweep.telemetry.replay import McapReplaySource

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", default=str(ROOT / "replay_logs" / "xv15_cruise_sweeps_da.mcap"))
    args = ap.parse_args(argv)

    chosen = read_channel_map(ROOT / "src" / "livesweep" / "data" / "xv15_channels.toml", one_clock=False)
    sp = chosen.signals, chosen.spectral
    settings = MonitorSettings(signals=sp[0], inputs=tuple(sp[1].inputs), outputs=tuple(sp[1].outputs),
                               band_rad_s=tuple(sp[1].band_rad_s), sample_rate_hz=sp[1].sample_rate_hz,
                               required_pairs=(("p", "da"),))
    pipe = MonitorPipeline(settings, [McapReplaySource(args.log, speed=0.0)], keep_estimates=1)
    summary = pipe.run()
    last = pipe.estimates[-1]
    print(f"{summary['frames']} frames, {summary['estimates']} estimates over {summary['data_s']:.0f} s of data")
    for k, out in enumerate(settings.outputs):
        for j, inp in enumerate(settings.inputs):
            print(f"  {out}/{inp}: median coherence {np.nanmedian(last.coherence[k, j]):.2f}")
    print(f"verdict: {pipe.verdict}")
    return summary, last, pipe.verdict


if __name__ == "__main__":
    main()
