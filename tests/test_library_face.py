"""The library face: identify(), array-first functions, python-control interop, the import graph.

Numbers are checked against python-control evaluating the converted systems, against the
analytic response the example simulates, and against the command line's report.
"""

import ast
import doctest
import importlib
import json
import pkgutil
import subprocess
import sys
from dataclasses import FrozenInstanceError
from pathlib import Path

import numpy as np
import pytest

import livesweep
from livesweep.errors import ConfigError

control = pytest.importorskip("control")

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "livesweep"


def _match_roots(a, b):
    """Largest distance between each root of ``a`` and its nearest neighbour in ``b`` (one to one)."""
    a, b = list(np.asarray(a, complex)), list(np.asarray(b, complex))
    assert len(a) == len(b)
    worst = 0.0
    for x in a:
        k = int(np.argmin([abs(x - y) for y in b]))
        worst = max(worst, abs(x - b.pop(k)))
    return worst


@pytest.fixture(scope="module")
def notebook():
    spec = importlib.util.spec_from_file_location("notebook_arrays", ROOT / "examples" / "notebook_arrays.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.main([])


@pytest.mark.slow
def test_notebook_fit_recovers_the_simulated_system(notebook):
    """p/da = 4 (s + 0.5) / (s^2 + 6 s + 36) e^(-0.04 s): the fit within 3 Cramer-Rao bounds (and 3 %)."""
    fit = notebook["fit"]
    truth = {"gain": 4.0, "1/T": 0.5, "zeta": 0.5, "w": 6.0, "tau": 0.04}
    for key, want in truth.items():
        got, cr = fit.parameters[key], fit.cramer_rao[key]
        assert abs(got - want) <= max(3 * cr, 0.03 * want), (key, got, want, cr)


@pytest.mark.slow
def test_to_tf_and_to_frd_agree_with_python_control(notebook):
    fit, data, T, frd = notebook["fit"], notebook["data"], notebook["tf"], notebook["frd"]
    w = np.geomspace(0.3, 40.0, 200)
    # python-control's evaluation of to_tf() times the delay is the fit's own response
    ctl = control.frequency_response(T, w).complex.ravel() * np.exp(-1j * w * fit.delay_s)
    np.testing.assert_allclose(ctl, fit.response(w), rtol=1e-9)
    # the Pade form is close where omega * tau is small
    Tp = fit.to_tf(pade_order=6)
    low = w < 20.0
    np.testing.assert_allclose(control.frequency_response(Tp, w[low]).complex.ravel(), fit.response(w[low]), rtol=1e-4)
    # to_frd holds the data's complex response at its frequencies, named
    ok = np.isfinite(data.H)
    np.testing.assert_allclose(frd.omega, data.omega[ok], rtol=1e-12)
    np.testing.assert_allclose(frd.complex.ravel(), data.H[ok], rtol=1e-12)
    assert frd.input_labels == ["da"] and frd.output_labels == ["p"]
    # and the fit lies on the data: within 3 random errors at 95 % of the coherent points
    coh = data.coherence[ok] >= 0.6
    rel = np.abs(fit.response(frd.omega[coh]) / frd.complex.ravel()[coh] - 1.0)
    assert np.mean(rel <= 3 * np.maximum(data.random_error[ok][coh], 0.01)) >= 0.95


@pytest.mark.slow
def test_to_ss_is_the_identified_model(notebook):
    ident, sys_ = notebook["ident"], notebook["ss"]
    fit = ident.state_space.fit
    assert _match_roots(control.poles(sys_), fit.eigenvalues) < 1e-9 * max(1.0, np.max(np.abs(fit.eigenvalues)))
    w = np.geomspace(0.3, 20.0, 50)
    ctl = control.frequency_response(sys_, w).complex                        # (outputs, inputs, freq)
    # delays only turn the phase: magnitudes agree exactly, and with the delays as Pade
    # approximants the complex response agrees where omega * tau is small
    np.testing.assert_allclose(np.abs(ctl), np.abs(fit.frequency_response(w)), rtol=1e-8, atol=1e-12)
    sys_p = fit.to_ss(pade_order=8)
    low = w < 10.0
    np.testing.assert_allclose(control.frequency_response(sys_p, w[low]).complex, fit.frequency_response(w[low]),
                               rtol=1e-4, atol=1e-9)
    assert list(sys_.state_labels) == list(fit.model.states) and list(sys_.input_labels) == list(fit.model.inputs)


@pytest.mark.slow
def test_identify_matches_the_command_line_report(cruise_identification, tmp_path):
    """identify() and `livesweep identify` compute the same model; the writer changes nothing."""
    from livesweep import cli

    ident = cruise_identification
    assert ident.stages == livesweep.STAGES
    before = list(ident.frequency_response.data_quality["notes"])
    path = livesweep.write_report(ident, tmp_path / "lib", plots=False)
    assert ident.frequency_response.data_quality["notes"] == before          # nothing mutated
    lib = json.loads(path.read_text())
    assert all(r["plot"] is None for r in lib["frequency_responses"]) and not list((tmp_path / "lib" / "plots").glob("*"))
    assert cli.main(["identify", str(ROOT / "config" / "xv15_cruise_lateral.toml"), "--out", str(tmp_path / "cli")]) == 0
    rep = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert rep["stages"] == lib["stages"]
    for a, b in zip(rep["state_space"]["parameters"], lib["state_space"]["parameters"]):
        assert a["name"] == b["name"] and a["value"] == pytest.approx(b["value"], rel=1e-6, abs=1e-9)
    assert rep["state_space"]["cost"]["average"] == pytest.approx(lib["state_space"]["cost"]["average"], rel=1e-6)
    with pytest.raises(FrozenInstanceError):
        ident.state_space = None
    assert ident.model is ident.state_space.fit or ident.residual.loop.added


def _fails(x):
    raise ConfigError(f"bad {x}")


def test_a_stage_run_in_a_forked_child_returns_its_value_or_raises_its_error():
    """identify() fits the transfer functions in a child process while the state-space stages run;
    the child's value and its one-line errors must come back as if it had run here."""
    import os
    import threading

    from livesweep.stages.background import Background as _Background

    forks = sys.platform.startswith("linux") and (os.cpu_count() or 1) >= 2 and threading.active_count() == 1
    pid = _Background(os.getpid).result()
    assert (pid != os.getpid()) == forks
    assert _Background(os.getpid, fork=False).result() == os.getpid()
    with pytest.raises(ConfigError, match="bad 7"):
        _Background(_fails, 7).result()


def test_identify_refuses_an_unknown_stage():
    with pytest.raises(ConfigError, match="until = 'fit'"):
        livesweep.identify(ROOT / "config" / "xv15_cruise_lateral.toml", until="fit")


def test_rerun_into_the_same_folder_leaves_no_stale_plots(cruise_identification, tmp_path):
    out = tmp_path / "r"
    livesweep.write_report(cruise_identification, out)
    n = len(list((out / "plots").glob("*.svg")))
    (out / "plots" / "old_pair.svg").write_text("<svg/>")
    (out / "plots" / "p_da.png").write_bytes(b"\x89PNG")               # a plot of an older version
    livesweep.write_report(cruise_identification, out)
    assert len(list((out / "plots").glob("*.svg"))) == n and not (out / "plots" / "old_pair.svg").exists()
    assert not list((out / "plots").glob("*.png"))


def test_frequency_response_from_arrays_checks_shapes_and_hands_out_read_only_arrays():
    rng = np.random.default_rng(3)
    u = rng.standard_normal(6000)
    frs = livesweep.frequency_response(u, 2.0 * u, sample_rate_hz=50.0, band_rad_s=(1.0, 20.0))
    H = frs.pair("y", "u").H
    np.testing.assert_allclose(H, 2.0, rtol=1e-9)                              # y = 2 u exactly
    with pytest.raises(ValueError):
        H[0] = 0.0
    a = frs.pair("y", "u").to_arrays()
    a["H"][0] = 0.0                                                           # copies are the user's
    with pytest.raises(ConfigError, match="same number of samples"):
        livesweep.frequency_response(u, u[:-1], sample_rate_hz=50.0, band_rad_s=(1.0, 20.0))
    with pytest.raises(ConfigError, match="2 signal\\(s\\) but 1 name"):
        livesweep.frequency_response(np.vstack([u, u]), u, sample_rate_hz=50.0, band_rad_s=(1.0, 20.0),
                                     input_names="da")
    bad = u.copy()
    bad[100] = np.nan
    with pytest.raises(ConfigError, match="^y: 1 non-finite"):
        livesweep.frequency_response(u, bad, sample_rate_hz=50.0, band_rad_s=(1.0, 20.0))
    with pytest.raises(ConfigError, match="expected one pair"):
        livesweep.fit_transfer_function(frs, denominator="(1/T)")


def test_state_space_model_from_matrices_equals_the_case_table():
    from livesweep.ident.state_space import StateSpaceModel

    tbl = StateSpaceModel.from_table({"states": ["v", "p"], "inputs": ["da"], "outputs": ["p", "ay"],
                                      "F": [["Yv", "0"], ["Lv", "Lp"]], "G": [["0"], ["Lda"]],
                                      "H": [["0", "r2d"], ["Yv", "0"]], "constants": {"r2d": 57.3},
                                      "parameters": {"Yv": -0.2, "Lv": -0.05, "Lp": -3.0, "Lda": 10.0}})
    mat = StateSpaceModel.from_matrices(states=["v", "p"], inputs=["da"], outputs=["p", "ay"],
                                        F=[["Yv", 0], ["Lv", "Lp"]], G=[[0.0], ["Lda"]], H=[[0, "r2d"], ["Yv", 0]],
                                        constants={"r2d": 57.3},
                                        parameters={"Yv": -0.2, "Lv": -0.05, "Lp": -3.0, "Lda": 10.0})
    w = np.geomspace(0.1, 30, 40)
    np.testing.assert_allclose(mat.frequency_response(mat.initial, w), tbl.frequency_response(tbl.initial, w), rtol=1e-12)
    with pytest.raises(ConfigError, match="F must be a 2-D matrix"):
        StateSpaceModel.from_matrices(states=["p"], inputs=["da"], outputs=["p"], F=["Lp"], G=[[1]], H=[[1]],
                                      parameters={"Lp": -1.0})


@pytest.mark.slow
def test_plot_functions_return_figures_and_leave_the_backend_alone(cruise_identification):
    import matplotlib
    from matplotlib.figure import Figure

    from livesweep.report.plots import bode_figure

    backend = matplotlib.get_backend()
    fig = bode_figure(cruise_identification.responses.pair("p", "da"))
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    assert matplotlib.get_backend() == backend
    code = "import matplotlib; matplotlib.use('svg'); import livesweep.report.writer, livesweep.report.plots; print(matplotlib.get_backend())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "svg"


# --- the import graph --------------------------------------------------------------------------

def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, modules: set) -> set:
    """livesweep modules ``path`` imports, anywhere but under ``if TYPE_CHECKING:``."""
    tree = ast.parse(path.read_text())
    skip = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
            for n in ast.walk(node)}
    me = _module_name(path)
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
                pkg = pkg[:len(pkg) - node.level + 1]
                base = ".".join(pkg + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return {m for m in out if m in modules and m != me}


@pytest.mark.slow
def test_no_import_cycle_among_livesweep_modules():
    files = {_module_name(f): f for f in SRC.rglob("*.py")}
    graph = {m: _imports(f, set(files)) for m, f in files.items()}
    state = {}

    def visit(m, path):
        state[m] = 1
        for d in sorted(graph[m]):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(d):] + [d]))
            if d not in state:
                visit(d, path + [d])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert "livesweep.cli" not in graph["livesweep.batch"]


def test_the_numerical_core_imports_no_io_package():
    core = [name for _, name, _ in pkgutil.walk_packages([str(SRC)], "livesweep.")
            if name.split(".")[1] in {"spectral", "ident", "consistency", "effects"}]
    io = ["mcap", "zenoh", "rerun", "pymavlink", "matplotlib", "livesweep.telemetry", "livesweep.cli",
          "livesweep.report", "livesweep.monitor"]
    code = (f"import sys, importlib\nfor m in {core!r}: importlib.import_module(m)\n"
            f"print(sorted({{k for k in sys.modules for p in {io!r} if k == p or k.startswith(p + '.')}}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert len(core) > 20 and out == "[]", out


def test_import_livesweep_is_light():
    code = "import sys, livesweep; print(sorted(k for k in sys.modules if k.split('.')[0] in ('numpy', 'scipy', 'livesweep')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "['livesweep']"


# --- examples in docstrings run --------------------------------------------------------------

@pytest.mark.parametrize("module", ["livesweep.arrays", "livesweep.ident.state_space"])
def test_docstring_examples_run(module, monkeypatch):
    monkeypatch.chdir(ROOT)
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


# --- the examples run as a user runs them ------------------------------------------------------

@pytest.mark.slow
def test_example_identify_case_recovers_the_simulated_aileron_delay(tmp_path):
    """The shipped cruise logs were simulated with a 0.0892 s aileron delay (replay_logs/regenerate.py)."""
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "identify_case.py"), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    line = next(ln for ln in out.stdout.splitlines() if ln.strip().startswith("tau_a"))
    value, cr_pct = float(line.split()[1]), float(line.split()[3])
    assert abs(value - 0.0892) <= 3 * cr_pct / 100 * value
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["stages"][-1] == "residual-loop" and (tmp_path / "report.html").is_file()


@pytest.mark.slow
def test_example_replay_judges_the_aileron_sweep_go():
    """A da sweep: p/da and phi/da coherent (the verdict GO names p/da as required); p/dr is not excited."""
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "replay_live.py")], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    coh = {ln.split(":")[0].strip(): float(ln.split()[-1]) for ln in out.stdout.splitlines() if "median coherence" in ln}
    assert coh["p/da"] > 0.9 and coh["phi/da"] > 0.9 and coh["p/dr"] < 0.5
    assert out.stdout.strip().splitlines()[-1] == "verdict: GO"


def test_stage_tables_are_parsed_once_and_fail_before_any_data_is_read(tmp_path):
    from livesweep.ident.state_space import StateSpaceModel
    from livesweep.stages.identify import parse_case_specs
    from livesweep.config import load_case

    case_path = ROOT / "config" / "xv15_cruise_lateral.toml"
    specs = parse_case_specs(load_case(case_path))
    assert isinstance(specs.state_space, StateSpaceModel) and specs.residual.enabled
    assert [t.model.name for t in specs.transfer_functions] == ["p_da"]
    bad = tmp_path / "bad.toml"
    bad.write_text(case_path.read_text().replace("../replay_logs/", str(ROOT / "replay_logs") + "/")
                   .replace("[transfer_functions.p_da]", "[transfer_functions.p_da]\ncolour = 'red'"))
    said = []
    with pytest.raises(ConfigError, match=r"bad\.toml: transfer_functions\.p_da.*colour"):
        livesweep.identify(bad, progress=said.append)
    assert said == []                                                   # nothing was read or computed
