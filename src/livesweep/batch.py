"""``livesweep batch``: many identifications in parallel, resumable, locally or on a Dask cluster.

Each case runs :func:`livesweep.identify` and :func:`livesweep.report.writer.write_report` into
``DIR/<case-name>`` in-process (its progress and summary going to ``DIR/<case-name>/identify.log``)
inside one function, :func:`run_one`, which a local process pool and a Dask cluster both call.
A case that finished is fingerprinted (case file, stage, livesweep version, every log it names)
in ``DIR/<case-name>/batch.json``; the next run skips it while the fingerprint still matches.
After every finished case ``DIR/summary.json`` (the rows) and ``DIR/summary.txt`` (a table) are
rewritten, so partial results survive a crash.

This is an edge module (files, processes, a cluster); the numerical core is untouched.
A Dask cluster must see the same file system as this machine (case files, logs and ``DIR`` at the
same paths) and should run one thread per worker process (``nthreads=1``): BLAS is the parallelism
inside one identification.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import re
import tempfile
import time
import tomllib
import traceback
from pathlib import Path

from livesweep import __version__
from livesweep.convert.common import sha256_of
from livesweep.errors import ConfigError
from livesweep.locks import folder_lock
from livesweep.numeric import finite_or_none as _finite_or_none
from livesweep.stages import STAGES

__all__ = ["find_cases", "fingerprint", "run_one", "run_batch", "summarize", "format_table",
           "add_batch_arguments", "cmd_batch", "BATCH_FILE", "LOG_FILE", "SUMMARY_JSON", "SUMMARY_TXT"]

BATCH_FILE = "batch.json"
LOG_FILE = "identify.log"
SUMMARY_JSON = "summary.json"
SUMMARY_TXT = "summary.txt"
_DEFAULT_STAGE = "residual-loop"
_CASE_HEADER = re.compile(r"^\s*\[\s*case\s*\]", re.MULTILINE)

#: content hash of a log by (resolved path, size, mtime_ns); cleared at the start of every run_batch
_LOG_HASHES: dict[tuple[str, int, int], str] = {}
#: one identification at a time per process (pyplot and sys.stdout are process-wide)


# --------------------------------------------------------------------------------------------
# cases, names, fingerprints
# --------------------------------------------------------------------------------------------


def _is_case_file(path: Path) -> bool:
    """A TOML file with a [case] table; one that does not parse counts when it has a [case] line
    (so a broken case file is reported as failed rather than silently skipped)."""
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError:
        return False
    try:
        return isinstance(tomllib.loads(text).get("case"), dict)
    except tomllib.TOMLDecodeError:
        return bool(_CASE_HEADER.search(text))


def find_cases(paths) -> list[Path]:
    """Case files named by ``paths``: files as given, folders by their ``*.toml`` files that hold a
    ``[case]`` table (channel maps and other TOML files are skipped; not recursive).

    Parameters
    ----------
    paths : iterable of str or os.PathLike

    Returns
    -------
    list of pathlib.Path
        Absolute, resolved, sorted, without duplicates.

    Raises
    ------
    ConfigError
        A path that does not exist (named).
    """
    found: set[Path] = set()
    for raw in paths:
        p = Path(raw).expanduser()
        if p.is_dir():
            found.update(f.resolve() for f in p.glob("*.toml") if f.is_file() and _is_case_file(f))
        elif p.is_file():
            found.add(p.resolve())
        else:
            raise ConfigError(f"case path {str(raw)!r} does not exist")
    return sorted(found)


def _case_name(case_path: Path) -> str:
    """[case].name when the file says so, else the file's stem (the case may be broken)."""
    try:
        name = tomllib.loads(Path(case_path).read_bytes().decode("utf-8"))["case"]["name"]
        if isinstance(name, str) and name.strip():
            return name
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, TypeError):
        pass
    return Path(case_path).stem


def _safe_name(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-")
    return s[:80] or "case"


def _read_batch_file(folder: Path) -> dict | None:
    try:
        d = json.loads((folder / BATCH_FILE).read_text())
        return d if isinstance(d, dict) else None
    except (OSError, ValueError):
        return None


def _assign_folders(cases: list[Path], out_dir: Path) -> list[str]:
    """One folder name per case: the safe case name, ``-2``, ``-3``... for clashes. A folder whose
    batch.json records the same case file stays that case's folder from run to run."""
    bases = [_safe_name(_case_name(c)) for c in cases]
    taken: set[str] = set()
    folders: list[str | None] = [None] * len(cases)

    def candidates(base):
        yield base
        k = 2
        while True:
            yield f"{base}-{k}"
            k += 1

    for k, (case, base) in enumerate(zip(cases, bases)):       # folders this case already owns
        for cand in candidates(base):
            info = _read_batch_file(out_dir / cand)
            if info is None and not (out_dir / cand).exists():
                break
            if info is not None and info.get("case") == str(case) and cand.lower() not in taken:
                folders[k] = cand
                taken.add(cand.lower())
                break
    for k, (case, base) in enumerate(zip(cases, bases)):       # the rest: first free name
        if folders[k] is not None:
            continue
        for cand in candidates(base):
            info = _read_batch_file(out_dir / cand)
            if cand.lower() not in taken and (info is None or info.get("case") in (None, str(case))):
                folders[k] = cand
                taken.add(cand.lower())
                break
    return folders  # type: ignore[return-value]


def _log_hash(path: Path) -> tuple[int, str]:
    st = path.stat()
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _LOG_HASHES:
        _LOG_HASHES[key] = sha256_of(path)
    return st.st_size, _LOG_HASHES[key]


def fingerprint(case_path, stage: str = _DEFAULT_STAGE) -> str:
    """SHA-256 of what an identification depends on: the case file's bytes, the last stage, the
    livesweep version and, for every log the case names (identify, then verify), its resolved
    path, size and content hash (cached per path, size and mtime within a run).

    Raises
    ------
    ConfigError
        When the case cannot be loaded (as :func:`livesweep.config.load_case`: a missing log is
        named).
    """
    from livesweep.config import load_case

    case = load_case(case_path)
    h = hashlib.sha256()

    def put(*items):
        for it in items:
            b = it if isinstance(it, bytes) else str(it).encode()
            h.update(len(b).to_bytes(8, "little") + b)

    put(b"livesweep.batch/1", case.path.read_bytes(), stage, __version__)
    for rec in tuple(case.identify) + tuple(case.verify):
        log = Path(rec.log).resolve()
        try:
            size, digest = _log_hash(log)
        except OSError as exc:
            raise ConfigError(f"{case.path}: log {log} cannot be read: {exc.strerror or exc}") from None
        put(log, size, digest)
    return h.hexdigest()


# --------------------------------------------------------------------------------------------
# one case
# --------------------------------------------------------------------------------------------




def summarize(ident) -> dict:
    """The summary numbers of one :class:`~livesweep.stages.identify.Identification`.

    Returns
    -------
    dict
        ``pairs`` (number of frequency responses), ``band_rad_s`` (``{"out/in": [lo, hi] or None}``,
        the widest adequate band by the case's criteria), ``J`` (J_ave of the final
        state-space model, the residual loop's when it added an effect; else the worst
        transfer-function cost, else None), ``TIC`` (the largest Theil inequality coefficient of
        that model over every verification record and output, or None) and ``residual`` (the
        residual loop's conclusion, or None).
    """
    band = {f"{a.output}/{a.input}": (list(a.widest_band_rad_s) if a.widest_band_rad_s else None)
            for a in ident.frequency_response.adequacy}
    J = None
    if ident.model is not None:
        J = _finite_or_none(ident.model.cost_average)
    if J is None and ident.transfer_functions is not None:
        costs = [c for c in (_finite_or_none(f.cost) for f in ident.transfer_functions.fits) if c is not None]
        J = max(costs) if costs else None
    results = ident.verification.results if ident.verification else ()
    if ident.residual is not None and ident.residual.verification_after:
        results = ident.residual.verification_after
    tics = [t for _, v in results for t in (_finite_or_none(o.tic) for o in v.outputs) if t is not None]
    return {"pairs": len(list(ident.responses.pairs())), "band_rad_s": band, "J": J,
            "TIC": max(tics) if tics else None,
            "residual": ident.residual.loop.conclusion if ident.residual is not None else None}


def _row(case_path, name, folder, out_dir, status, *, error=None, seconds=0.0, stage=_DEFAULT_STAGE, summary=None):
    row = {"case": str(case_path), "name": name, "out": str(Path(out_dir) / folder) if folder else None,
           "stage": stage, "status": status, "error": error, "seconds": round(float(seconds), 3),
           "pairs": None, "band_rad_s": None, "J": None, "TIC": None, "residual": None}
    if summary:
        row.update(summary)
    return row


def _one_line(exc: BaseException) -> str:
    from livesweep.errors import LivesweepError

    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    if not isinstance(exc, LivesweepError):
        msg = f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__
    return msg[:400]


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".partial")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _skip_row(case_path: Path, name: str, folder: str, out_dir: Path, stage: str, fp: str | None):
    """The "skipped" row when DIR/folder holds a successful run with this fingerprint, else None."""
    if fp is None:
        return None
    t0 = time.monotonic()
    case_dir = out_dir / folder
    info = _read_batch_file(case_dir)
    if not info or info.get("fingerprint") != fp or info.get("status") != "ok" or not (case_dir / "report.json").is_file():
        return None
    stored = info.get("row") if isinstance(info.get("row"), dict) else {}
    return _row(case_path, name, folder, out_dir, "skipped", seconds=time.monotonic() - t0, stage=stage,
                summary={k: stored.get(k) for k in ("pairs", "band_rad_s", "J", "TIC", "residual")})


def _write_batch_file(case_dir: Path, case_path: Path, fp: str | None, row: dict) -> None:
    with contextlib.suppress(OSError):
        case_dir.mkdir(parents=True, exist_ok=True)
        _atomic_write(case_dir / BATCH_FILE, json.dumps(
            {"format": "livesweep.batch/1", "case": str(case_path), "fingerprint": fp if row["status"] == "ok" else None,
             "status": row["status"], "stage": row["stage"], "livesweep_version": __version__,
             "finished_unix_s": round(time.time(), 3), "row": row}, indent=1, allow_nan=False))


def run_one(case_path, out_dir, stage: str = _DEFAULT_STAGE, folder: str | None = None, force: bool = False,
            fp: str | None = None, plots: bool = True) -> dict:
    """Identify one case into ``out_dir/<folder>``, in this process; never raises.

    Parameters
    ----------
    case_path : str or Path
        The case file.
    out_dir : str or Path
        The batch folder; the case's report goes to ``out_dir/<folder>``.
    stage : str
        Last stage to run (``livesweep.stages.STAGES``).
    folder : str, optional
        The case's folder name (:func:`run_batch` assigns unique ones); default the case name made
        file-system safe.
    force : bool
        Run even when ``batch.json`` there holds this case's current fingerprint and a report.
    fp : str, optional
        The case's :func:`fingerprint`, when the caller computed it already.
    plots : bool
        False writes the reports without plots (faster; ``report.json`` is the same).

    Returns
    -------
    dict
        ``{case, name, out, stage, status ("ok", "skipped" or "failed"), error (one line, failed
        only), seconds, pairs, band_rad_s, J, TIC, residual}`` (see :func:`summarize`).
    """
    t0 = time.monotonic()
    case_path, out_dir = Path(case_path).resolve(), Path(out_dir).resolve()
    name = _case_name(case_path)
    folder = folder or _safe_name(name)
    case_dir = out_dir / folder
    try:
        if fp is None:
            fp = fingerprint(case_path, stage)
        if not force:
            skipped = _skip_row(case_path, name, folder, out_dir, stage, fp)
            if skipped is not None:
                return skipped
        if stage not in STAGES:
            raise ConfigError(f"stage {stage!r} is not one of {', '.join(STAGES)}")
        case_dir.mkdir(parents=True, exist_ok=True)
        (case_dir / BATCH_FILE).unlink(missing_ok=True)   # no stale "done" while this run is under way
    except Exception as exc:  # noqa: BLE001 - a batch reports every failure as a row
        row = _row(case_path, name, folder, out_dir, "failed", error=_one_line(exc),
                   seconds=time.monotonic() - t0, stage=stage)
        _write_log_and_batch(case_dir, case_path, None, row, traceback.format_exc())
        return row
    try:
        with open(case_dir / LOG_FILE, "w", buffering=1) as log:
            try:
                from livesweep.stages.identify import identify
                from livesweep.report.console import summary_lines
                from livesweep.report.writer import write_report

                def progress(msg):
                    log.write(f"[{time.monotonic() - t0:6.1f} s] {msg}\n")

                ident = identify(case_path, until=stage, progress=progress, parallel=False)   # a case per core already
                progress("writing the report" + ("" if plots else " (no plots)"))
                path = write_report(ident, case_dir, plots=plots)
                log.write("\n".join(summary_lines(ident)) + f"\nwrote {path} and {path.parent / 'report.html'}\n")
                row = _row(case_path, name, folder, out_dir, "ok", seconds=time.monotonic() - t0, stage=stage,
                           summary=summarize(ident))
            except Exception as exc:  # noqa: BLE001
                log.write("\n" + traceback.format_exc())
                row = _row(case_path, name, folder, out_dir, "failed", error=_one_line(exc),
                           seconds=time.monotonic() - t0, stage=stage)
    except OSError as exc:                                  # the log itself cannot be written
        row = _row(case_path, name, folder, out_dir, "failed", error=_one_line(exc),
                   seconds=time.monotonic() - t0, stage=stage)
    _write_batch_file(case_dir, case_path, fp, row)
    return row


def _write_log_and_batch(case_dir: Path, case_path: Path, fp, row: dict, text: str) -> None:
    with contextlib.suppress(OSError):
        case_dir.mkdir(parents=True, exist_ok=True)
        (case_dir / LOG_FILE).write_text(f"{row['error']}\n\n{text}")
    _write_batch_file(case_dir, case_path, fp, row)


# --------------------------------------------------------------------------------------------
# many cases
# --------------------------------------------------------------------------------------------


def _fmt(x, spec):
    width = int(re.match(r"\d*", spec).group() or 0)
    return f"{'-':>{width}s}" if x is None else format(x, spec)


def _band_text(bands) -> str:
    ok = [b for b in (bands or {}).values() if b]
    if not ok:
        return "-"
    return f"{min(b[0] for b in ok):.2f}..{max(b[1] for b in ok):.2f}"


def format_table(rows: list[dict]) -> str:
    """Fixed-width table of batch rows: case, status, pairs (adequate/all), band (the span of the
    pairs' widest adequate bands, rad/s), J, TIC, residual, seconds; failed rows add their error."""
    head = f"{'case':32s} {'status':8s} {'pairs':>5s} {'band rad/s':>13s} {'J':>8s} {'TIC':>6s}  {'residual':36s} {'seconds':>8s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        bands = r.get("band_rad_s") or {}
        pairs = "-" if r.get("pairs") is None else f"{sum(1 for b in bands.values() if b)}/{r['pairs']}"
        resid = r.get("residual") or "-"
        resid = resid if len(resid) <= 36 else resid[:35] + "~"
        name = str(r.get("name") or "")
        name = name if len(name) <= 32 else name[:31] + "~"
        lines.append(f"{name:32s} {r['status']:8s} {pairs:>5s} {_band_text(bands):>13s} {_fmt(r.get('J'), '8.1f')} "
                     f"{_fmt(r.get('TIC'), '6.3f')}  {resid:36s} {r.get('seconds', 0.0):8.1f}")
        if r["status"] == "failed" and r.get("error"):
            lines.append(f"{'':32s} error: {r['error']}")
    return "\n".join(lines) + "\n"


def _write_summary(out_dir: Path, rows: list[dict]) -> None:
    _atomic_write(out_dir / SUMMARY_JSON, json.dumps(rows, indent=1, allow_nan=False))
    _atomic_write(out_dir / SUMMARY_TXT, format_table(rows))


def _init_worker(blas_threads: int) -> None:
    """Keep each worker's BLAS/OpenMP pools to its share of the cores (unless the user chose)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(blas_threads))


def _mp_context():
    import multiprocessing as mp

    return mp.get_context("forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn")


def _run_local(jobs, out_dir, stage, force, workers, finish, plots=True):
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    n_cpu = os.cpu_count() or 1
    n = max(1, min(workers or n_cpu, len(jobs)))
    crashed = []

    def pool(n_workers):
        return ProcessPoolExecutor(max_workers=n_workers, mp_context=_mp_context(), initializer=_init_worker,
                                   initargs=(max(1, n_cpu // n_workers),))

    ex = pool(n)
    try:
        futs = {ex.submit(run_one, str(c), str(out_dir), stage, folder, force, fp, plots): (k, c, name, folder)
                for k, c, name, folder, fp in jobs}
        for fut in as_completed(futs):
            k, c, name, folder = futs[fut]
            try:
                finish(k, fut.result())
            except BrokenProcessPool:
                crashed.append(next(j for j in jobs if j[0] == k))
            except Exception as exc:  # noqa: BLE001
                finish(k, _row(c, name, folder, out_dir, "failed", error=_one_line(exc), stage=stage))
    except BaseException:
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    ex.shutdown(wait=True)
    # a worker died (segfault, out of memory): the pool broke for every case in flight; run those
    # again one per fresh process so only the one that kills its process fails
    for k, c, name, folder, fp in sorted(crashed):
        with pool(1) as ex1:
            try:
                row = ex1.submit(run_one, str(c), str(out_dir), stage, folder, force, fp, plots).result()
            except Exception as exc:  # noqa: BLE001
                row = _row(c, name, folder, out_dir, "failed", stage=stage,
                           error=f"the worker process died: {_one_line(exc)}")
        finish(k, row)


def _run_dask(jobs, out_dir, stage, force, address, finish, plots=True):
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ConfigError("--dask needs dask.distributed: pip install 'livesweep[dask]'") from None
    try:
        client = Client(address, timeout="30s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"--dask {address!r}: cannot connect to the Dask scheduler: {exc}") from None
    with client:
        cols = list(zip(*[(str(c), str(out_dir), stage, folder, force, fp, plots) for _, c, _, folder, fp in jobs]))
        futs = client.map(run_one, *cols, pure=False)
        where = {f.key: job for f, job in zip(futs, jobs)}
        for fut in as_completed(futs):
            k, c, name, folder, _ = where[fut.key]
            try:
                row = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker died (KilledWorker) or similar
                row = _row(c, name, folder, out_dir, "failed", error=_one_line(exc), stage=stage)
            finish(k, row)
            fut.release()


def run_batch(cases, out_dir, *, stage: str = _DEFAULT_STAGE, workers: int | None = None,
              dask_address: str | None = None, progress=None, force: bool = False, plots: bool = True) -> list[dict]:
    """Identify many cases in parallel into ``out_dir/<case-name>``; resumable.

    Parameters
    ----------
    cases : iterable of str or Path
        Case files (see :func:`find_cases` for folders).
    out_dir : str or Path
        The batch folder (created). Holds one folder per case, ``summary.json`` and ``summary.txt``.
    stage : str
        Last stage to run for every case (``livesweep.stages.STAGES``).
    workers : int, optional
        Local worker processes (default: the number of CPUs). Ignored with ``dask_address``.
    dask_address : str, optional
        A Dask scheduler (``tcp://host:8786``): run the cases on its workers instead.
    progress : callable, optional
        ``progress(done, total, row)`` after every finished (or skipped) case.
    force : bool
        Run every case, even those whose stored fingerprint is current.
    plots : bool
        False writes every report without plots (faster; ``report.json`` is the same).

    Returns
    -------
    list of dict
        One row per case, in case order (see :func:`run_one`).

    Raises
    ------
    ConfigError
        An unknown stage, an unusable ``out_dir`` (or one another batch is writing into), no dask
        installed or no scheduler at ``dask_address``. A failing case never raises: its row says
        ``failed`` and why.
    """
    if stage not in STAGES:
        raise ConfigError(f"stage {stage!r} is not one of {', '.join(STAGES)}")
    if workers is not None and workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers!r}")
    cases = [Path(c).expanduser().resolve() for c in cases]
    out_dir = Path(out_dir).expanduser().resolve()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {str(out_dir)!r} cannot be created: {exc.strerror or exc}") from None
    if not os.access(out_dir, os.W_OK):
        raise ConfigError(f"--out {str(out_dir)!r} is not writable")
    with folder_lock(out_dir):
        return _run_locked(cases, out_dir, stage, workers, dask_address, progress, force, plots)


def _run_locked(cases, out_dir, stage, workers, dask_address, progress, force, plots=True) -> list[dict]:
    """:func:`run_batch` once the batch folder is made and locked."""
    _LOG_HASHES.clear()
    folders = _assign_folders(cases, out_dir)
    total = len(cases)
    rows: list[dict | None] = [None] * total
    done = 0

    def finish(k, row):
        nonlocal done
        rows[k] = row
        done += 1
        _write_summary(out_dir, [r for r in rows if r is not None])
        if progress is not None:
            progress(done, total, row)

    jobs = []
    for k, (case, folder) in enumerate(zip(cases, folders)):
        name = _case_name(case)
        t0 = time.monotonic()
        try:
            fp = fingerprint(case, stage)
        except Exception as exc:  # noqa: BLE001 - the case cannot even be loaded: it fails here, as it would there
            row = _row(case, name, folder, out_dir, "failed", error=_one_line(exc), seconds=time.monotonic() - t0,
                       stage=stage)
            _write_log_and_batch(out_dir / folder, case, None, row, traceback.format_exc())
            finish(k, row)
            continue
        skipped = None if force else _skip_row(case, name, folder, out_dir, stage, fp)
        if skipped is not None:
            finish(k, skipped)
        else:
            jobs.append((k, case, name, folder, fp))
    if jobs:
        if dask_address:
            _run_dask(jobs, out_dir, stage, force, dask_address, finish, plots)
        else:
            _run_local(jobs, out_dir, stage, force, workers, finish, plots)
    if not rows:
        _write_summary(out_dir, [])
    return rows  # type: ignore[return-value]


# --------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------


def add_batch_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``livesweep batch`` on ``parser`` (a subparser); sets ``func=cmd_batch``."""
    parser.add_argument("cases", nargs="+", help="case files (TOML) or folders of them")
    parser.add_argument("--out", required=True, help="batch folder: one report folder per case, summary.json, summary.txt")
    parser.add_argument("--workers", type=int, help="local worker processes (default: one per CPU)")
    parser.add_argument("--dask", metavar="ADDRESS", help="run on a Dask cluster, e.g. tcp://scheduler:8786 "
                        "(same file system; pip install 'livesweep[dask]')")
    parser.add_argument("--stage", default=_DEFAULT_STAGE, choices=list(STAGES),
                        help="last stage to run (default: every stage each case defines)")
    parser.add_argument("--force", action="store_true", help="re-run cases whose results are current")
    parser.add_argument("--no-plots", dest="plots", action="store_false",
                        help="write the reports without plots (report.json is the same; about half the time)")
    parser.set_defaults(func=cmd_batch)
    return parser


def cmd_batch(args) -> int:
    """Run the batch with a text progress line per case and the final table; 0 when every case is
    ok or skipped, 1 when any failed."""
    cases = find_cases(args.cases)
    if not cases:
        raise ConfigError(f"no case files (TOML with a [case] table) in {', '.join(map(str, args.cases))}")
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    where = f"Dask cluster {args.dask}" if args.dask else f"{args.workers or os.cpu_count()} local worker(s)"
    print(f"livesweep batch: {len(cases)} case(s) to stage {args.stage} on {where} -> {args.out}", flush=True)
    width = len(str(len(cases)))

    def progress(done, total, row):
        extra = f": {row['error']}" if row["status"] == "failed" else ""
        print(f"[{done:{width}d}/{total}] {row['name']} {row['status']} ({row['seconds']:.1f} s){extra}", flush=True)

    rows = run_batch(cases, args.out, stage=args.stage, workers=args.workers, dask_address=args.dask,
                     progress=progress, force=args.force, plots=args.plots)
    print()
    print(format_table(rows), end="")
    out = Path(args.out)
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "failed")}
    print(f"{counts['ok']} ok, {counts['skipped']} skipped, {counts['failed']} failed; "
          f"wrote {out / SUMMARY_JSON} and {out / SUMMARY_TXT}")
    return 1 if counts["failed"] else 0
