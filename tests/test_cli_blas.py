"""identify, batch and demo run BLAS single-threaded (their linear algebra is many small
problems; a thread pool stalls the SVDs of the residual loop's fits): the variables must be set
before numpy loads, which the command-line parser itself does."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow                 # every test of this module takes over 1 s

ROOT = Path(__file__).resolve().parents[1]

_PROBE = """
import builtins, os, sys
seen = {}
orig = builtins.__import__
def imp(name, *a, **k):
    if name.split(".")[0] == "numpy" and "numpy" not in sys.modules and "v" not in seen:
        seen["v"] = os.environ.get("OPENBLAS_NUM_THREADS")
    return orig(name, *a, **k)
builtins.__import__ = imp
from livesweep.cli import main
code = main(sys.argv[1:])
print("BLAS threads at numpy import:", seen.get("v"), "exit", code)
"""


def _probe(tmp_path, *args, env_extra=None):
    import os

    blas = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    env = {k: v for k, v in os.environ.items() if k not in blas}
    env.update(env_extra or {})
    r = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, env=env, timeout=300)
    return r.stdout.strip().splitlines()[-1] if r.stdout.strip() else r.stderr


def test_identify_loads_numpy_with_single_threaded_blas(tmp_path):
    case = str(ROOT / "config" / "xv15_cruise_lateral.toml")
    args = ("identify", case, "--out", str(tmp_path / "o"), "--stage", "frequency-response", "--no-plots")
    assert _probe(tmp_path, *args) == "BLAS threads at numpy import: 1 exit 0"


def test_a_users_own_blas_setting_is_kept_and_other_verbs_are_left_alone(tmp_path):
    case = str(ROOT / "config" / "xv15_cruise_lateral.toml")
    args = ("identify", case, "--out", str(tmp_path / "o"), "--stage", "frequency-response", "--no-plots")
    assert _probe(tmp_path, *args, env_extra={"OPENBLAS_NUM_THREADS": "2"}) == "BLAS threads at numpy import: 2 exit 0"
    got = _probe(tmp_path, "maps")
    assert got.startswith("BLAS threads at numpy import: None")
