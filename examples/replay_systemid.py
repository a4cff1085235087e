"""An ArduPilot SystemID flight log through the live monitor, from a script: ``livesweep convert`` then
``livesweep replay --map ardupilot-sysid-dataflash``, as two library calls.

    python examples/replay_systemid.py [LOG.bin] [--out DIR]

Default: the shared ArduCopter SITL SystemID log (axis 7, rate roll:
``../shared/data/ardupilot_sitl_systemid/sid_axis7_rate_roll.bin``); without it the example
says so and stops. Prints each test point the monitor found, its verdict and why, then the
operator's verdict at the end.
"""

import argparse
import logging
import tempfile
from pathlib import Path

import livesweep
from livesweep.convert import convert

ROOT = Path(__file__).resolve().parents[1]
SHARED_LOG = Path("ardupilot_sitl_systemid") / "sid_axis7_rate_roll.bin"


def shared_log():
    """The shared SITL log, or None when the shared data is not next to this checkout."""
    for base in (ROOT.parent / "shared" / "data", Path("/work/shared/data")):
        if (base / SHARED_LOG).is_file():
            return base / SHARED_LOG
    return None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", help=f"an ArduPilot DataFlash .bin (default: the shared {SHARED_LOG})")
    ap.add_argument("--out", help="folder for the converted MCAP (default: a new temporary folder)")
    args = ap.parse_args(argv)

    log = Path(args.log) if args.log else shared_log()
    if log is None:
        print(f"skipped: the shared data is absent (../shared/data/{SHARED_LOG}); give a DataFlash .bin instead")
        return None
    # the monitor's warnings (a signal the map names has no frames yet) are kept as result.alerts too
    logging.getLogger("livesweep").setLevel(logging.ERROR)
    out = Path(args.out or tempfile.mkdtemp(prefix="livesweep-example-"))
    mcap = out / (log.stem + ".mcap")
    convert(log, mcap, force=True)              # what `livesweep convert LOG --out X.mcap --force` does
    print(f"converted {log.name} -> {mcap}")

    result = livesweep.replay(mcap, map="ardupilot-sysid-dataflash")
    s = result.summary
    print(f"replayed {s['frames']} frames, {s['estimates']} estimates over {s['data_s']:.1f} s of data "
          f"(settings: {result.settings_source} {result.settings.map_name})")
    for k, tp in enumerate(result.test_points, 1):
        why = tp["reasons"][:1] or tp["missing"][:1]
        print(f"TP{k} {tp['swept_input']} ({tp['source']}, {tp['start_s']:.1f} s - {tp['end_s']:.1f} s): "
              f"{tp['verdict']}" + (f" ({why[0]})" if tp["verdict"] != "GO" and why else ""))
    kinds = sorted({a["kind"] for a in result.alerts})
    print(f"{len(result.alerts)} alerts ({', '.join(kinds) or 'none'}), {len(result.verdicts)} verdict changes")
    print(f"verdict: {result.verdict}")
    return result


if __name__ == "__main__":
    main()
