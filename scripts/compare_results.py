"""Snapshot what livesweep computes on its shipped inputs, and compare two snapshots number by number.

A refactor must leave every number the same. This script records, from whichever livesweep is
importable (set ``PYTHONPATH`` to another checkout's ``src`` to snapshot that one):

- ``report.json`` of every shipped case in ``config/`` (``livesweep identify --no-plots``);
- the test points the monitor closes when it replays each shipped log in ``replay_logs/`` (the
  packaged XV-15 map) and, when the shared data is next to this checkout, the ArduPilot SITL
  SystemID logs (the ``ardupilot-sysid-dataflash`` map).

    python scripts/compare_results.py snapshot OUT_DIR
    python scripts/compare_results.py compare BEFORE_DIR AFTER_DIR [--rtol 1e-6]

``compare`` walks both snapshots: every number must agree within ``rtol`` (relative, with an
absolute floor of ``rtol`` times the largest magnitude in the same array), every string and every
key present before must be present after. Keys only in the newer snapshot are listed as additions
(new fields are not changes). Wall-clock times, paths and versions are ignored. Exit status 1 on
any difference.
"""

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "ardupilot_sitl_systemid"
IGNORED = {"wall_s", "elapsed_s", "seconds", "version", "livesweep_version", "created", "path", "log", "out",
           "case_file", "generated", "python", "numpy", "scipy", "timings", "wall_time_s", "cpu_s", "host",
           "recording", "files", "output", "report_html", "plots", "generated_utc"}


def shipped_cases():
    return sorted(p for p in (ROOT / "config").glob("*.toml") if "[case]" in p.read_text())


def _replay_test_points(log, map_name=None):
    """The test points the monitor closes on ``log``, as ``/livesweep/test_point`` records them."""
    from mcap.reader import make_reader

    from livesweep.telemetry.recorder import McapRecorder
    try:
        from livesweep.monitor.session import map_settings
        settings = map_settings(None, map_name)
    except ImportError:                       # an older checkout: the CLI built the settings
        from livesweep import cli
        ns = argparse.Namespace(case=None, map=map_name, window=None, update_period=None, sysid=None,
                                saturation=None, require=None)
        settings = cli._monitor_settings(ns)
    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.replay import McapReplaySource

    with tempfile.TemporaryDirectory() as tmp:
        rec = McapRecorder(Path(tmp) / "r.mcap", settings=settings.to_dict())
        MonitorPipeline(settings, [McapReplaySource(str(log), speed=0.0)], recorder=rec).run()
        points = []
        with open(Path(tmp) / "r.mcap", "rb") as fh:
            for _schema, channel, message in make_reader(fh).iter_messages(topics=["/livesweep/test_point"]):
                points.append(json.loads(message.data))
    return points


def _preparation(case: Path) -> list[list[str]]:
    """The ``livesweep convert`` / ``livesweep sim`` commands a case's header comment says to run
    first (its logs are not committed), as argument lists."""
    commands, current = [], ""
    for line in case.read_text().splitlines():
        if not line.startswith("#"):
            break
        text = line.lstrip("#").strip()
        if current or text.startswith("livesweep "):
            current += " " + text.rstrip("\\").strip()
            if not text.endswith("\\"):
                if not current.split()[1] == "identify":
                    commands.append(current.split())
                current = ""
    return commands


def snapshot(out: Path) -> None:
    """Identify every shipped case (after the commands its header asks for, run in a scratch copy
    of config/ and replay_logs/) and replay every shipped log."""
    import shutil

    out.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp())
    for d in ("config", "replay_logs"):
        shutil.copytree(ROOT / d, scratch / d)
    for case in shipped_cases():
        for cmd in _preparation(case):
            args = [a.replace("../shared/data", str(ROOT.parent / "shared" / "data")) for a in cmd[1:]]
            subprocess.run([sys.executable, "-m", "livesweep", *args], cwd=scratch, capture_output=True, text=True)
        dest = out / "cases" / case.stem
        run = subprocess.run([sys.executable, "-m", "livesweep", "identify", str(scratch / "config" / case.name),
                              "--out", str(dest), "--no-plots"], capture_output=True, text=True)
        status = "ok" if run.returncode == 0 else f"exit {run.returncode}: {run.stderr.strip()[-300:]}"
        print(f"identify {case.name}: {status}", flush=True)
    logs = [(p, None) for p in sorted((ROOT / "replay_logs").glob("*.mcap"))]
    if SHARED.is_dir():
        from livesweep.convert import convert
        tmp = Path(tempfile.mkdtemp())
        for p in sorted(SHARED.glob("*.bin")):
            mcap = tmp / (p.stem + ".mcap")
            convert(str(p), str(mcap))
            logs.append((mcap, "ardupilot-sysid-dataflash"))
    replays = {}
    for log, map_name in logs:
        replays[log.stem] = _replay_test_points(log, map_name)
        print(f"replay {log.name}: {len(replays[log.stem])} test points", flush=True)
    (out / "replays.json").write_text(json.dumps(replays, indent=1, sort_keys=True))


def _walk(a, b, where, rtol, diffs, added, scale=None):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in a:
            if k in IGNORED:
                continue
            if k not in b:
                diffs.append(f"{where}.{k}: missing after")
            else:
                _walk(a[k], b[k], f"{where}.{k}", rtol, diffs, added)
        added.extend(f"{where}.{k}" for k in b if k not in a and k not in IGNORED)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            diffs.append(f"{where}: {len(a)} items before, {len(b)} after")
            return
        nums = [abs(x) for x in a if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)]
        big = max(nums, default=None)
        for i, (x, y) in enumerate(zip(a, b)):
            _walk(x, y, f"{where}[{i}]", rtol, diffs, added, big)
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if math.isnan(a) and math.isnan(b):
            return
        floor = rtol * (scale if scale else 0.0) + 1e-12
        if not (abs(a - b) <= rtol * max(abs(a), abs(b)) + floor):
            diffs.append(f"{where}: {a!r} before, {b!r} after")
    elif a != b:
        diffs.append(f"{where}: {a!r} before, {b!r} after")


def compare(before: Path, after: Path, rtol: float) -> int:
    diffs, added = [], []
    for rep in sorted((before / "cases").glob("*/report.json")):
        other = after / "cases" / rep.parent.name / "report.json"
        if not other.is_file():
            diffs.append(f"{rep.parent.name}: no report after")
            continue
        _walk(json.loads(rep.read_text()), json.loads(other.read_text()), rep.parent.name, rtol, diffs, added)
    a, b = (json.loads((d / "replays.json").read_text()) for d in (before, after))
    _walk(a, b, "replays", rtol, diffs, added)
    n_reports = len(list((before / "cases").glob("*/report.json")))
    n_points = sum(len(v) for v in a.values())
    print(f"compared {n_reports} reports and {n_points} replayed test points at rtol {rtol:g}")
    if added:
        print(f"{len(added)} fields only after (additions, not changes), e.g. " + ", ".join(added[:6]))
    for d in diffs[:60]:
        print("DIFF", d)
    print(f"{len(diffs)} differences")
    return 1 if diffs else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="verb", required=True)
    sub.add_parser("snapshot").add_argument("out", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--rtol", type=float, default=1e-6)
    args = ap.parse_args(argv)
    if args.verb == "snapshot":
        snapshot(args.out)
        return 0
    return compare(args.before, args.after, args.rtol)


if __name__ == "__main__":
    sys.exit(main())
