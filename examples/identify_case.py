"""Identify a case file from Python and write its report: what ``livesweep identify`` does.

    python examples/identify_case.py [CASE.toml] [--out DIR]

Default: the shipped XV-15 cruise case (its logs are in ``replay_logs/``).
"""

import argparse
import tempfile
from pathlib import Path

import livesweep

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", nargs="?", default=str(ROOT / "config" / "xv15_cruise_lateral.toml"))
    ap.add_argument("--out", default=None, help="report folder (default: a new temporary folder)")
    args = ap.parse_args(argv)

    ident = livesweep.identify(args.case, progress=print)
    fit = ident.model                            # after the residual loop when it added an effect
    print(f"\n{ident.case.name}: stages {', '.join(ident.stages)} in {ident.elapsed_s:.1f} s")
    print(f"J_ave {fit.cost_average:.2f}; eigenvalues {', '.join(f'{e:.3f}' for e in fit.eigenvalues)}")
    for p in fit.parameters:
        if not p.fixed:
            print(f"  {p.name:8s} {p.value:10.4g}   CR {p.cramer_rao_pct:5.1f} %")
    if ident.residual is not None:
        print(f"residual loop: {ident.residual.loop.conclusion}")
    out = Path(args.out or tempfile.mkdtemp(prefix="livesweep-example-"))
    path = livesweep.write_report(ident, out)
    print(f"wrote {path} and {out / 'report.html'}")
    return ident, path


if __name__ == "__main__":
    main()
