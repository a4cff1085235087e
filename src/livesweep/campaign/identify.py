"""``campaign identify``: the selected test points of one input, across flights, in one identification.

The test points a query of the campaign selects (:meth:`Campaign.test_points`: one swept input,
its verdict, flights, conditions) become one case with one ``[[identify]]`` record per test point
(:func:`livesweep.campaign.concat.identify_test_points`): the method's multi-run concatenation.
Each record is the test point with :data:`TRIM_PAD_S` of the flight before and after it (the
records are joined end to end and windows span the joins, so each must start and end in trim).
A flight that is not MCAP (a DataFlash ``.bin``, a ``.tlog``) is converted once into
``converted/<sha256>.mcap`` next to the database. The report is written as ``livesweep identify``
writes it, and the result is stored in the campaign (``results``, kind ``identification``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["identify_selection", "identify_all", "CampaignIdentification", "TRIM_PAD_S"]

#: Trim taken before and after each test point [s] (method §2.2: about 3 s of trim at each end).
TRIM_PAD_S = 3.0


@dataclass(frozen=True)
class CampaignIdentification:
    """What ``campaign identify`` did.

    Attributes
    ----------
    identification : Identification
    report : pathlib.Path
        The ``report.json`` written.
    test_points : tuple of TestPointRow
        The test points concatenated, in order.
    result_id : int
        Its row in the campaign's ``results``.
    """

    identification: object
    report: Path
    test_points: tuple
    result_id: int


def _mcap_of(campaign, row) -> Path:
    """The MCAP of a test point's flight: the file itself, or its conversion next to the database."""
    path = Path(row.flight_path)
    sha, fmt = campaign.connection.execute("SELECT sha256, format FROM flights WHERE id = ?",
                                           (row.flight_id,)).fetchone()
    if fmt == "mcap":
        return path
    out = Path(campaign.path).parent / "converted" / f"{sha}.mcap"
    if not out.is_file():
        from livesweep.convert import convert

        out.parent.mkdir(parents=True, exist_ok=True)
        convert(path, out)
    return out


def _usable(campaign, map, *, verdict="usable", axis=None, flight=None, conditions=None) -> list:
    """``(row, swept input)`` of the test points the filters select whose input is known (a run found
    offline takes it from the map's ``[test_points] axes``) and whose signals the log holds."""
    from livesweep.maps import load_map

    chosen = load_map(map) if isinstance(map, (str, Path)) else map
    axes = dict(chosen.test_points.axes) if chosen.test_points is not None else {}
    out = []
    for r in campaign.test_points(verdict=None if verdict == "usable" else verdict, axis=axis, flight=flight,
                                  conditions=conditions):
        inp = swept_input_of(r.swept_input, r.axis, axes)
        if inp and usable(r.start_s, r.end_s, r.record_dict, None if verdict != "usable" else r.verdict):
            out.append((r, inp))
    return out


def swept_input_of(swept_input, axis, axes: dict):
    """The input a test point sweeps: its own, or for a run found offline the map's ``axes`` entry."""
    return swept_input or axes.get(axis)


def usable(start_s, end_s, record: dict, verdict) -> bool:
    """A test point that can be identified: its span is known, its log holds the signals of the run,
    and it is GO or not judged (``verdict`` None: not asked)."""
    return (start_s is not None and end_s is not None and (record or {}).get("data", True) is not False
            and verdict in (None, "GO"))


def identify_all(campaign, out_dir, *, map, verdict: str | None = "usable", workers: int | None = None,
                 dask_address: str | None = None, pad_s: float = TRIM_PAD_S, progress=None) -> list[dict]:
    """Every swept input's selected test points, concatenated, as one case each, identified on the
    batch engine (:func:`livesweep.batch.run_batch`: a process pool, or a Dask cluster).

    Writes ``out_dir/cases/<input>.toml`` and the reports under ``out_dir/reports``; returns the
    batch's rows (one per input: status, pairs, coherent band, J). Parameters as
    :func:`identify_selection`; ``workers`` and ``dask_address`` as ``livesweep batch``.
    """
    from livesweep.batch import run_batch
    from livesweep.campaign.concat import TestPointRef, case_text_for_map

    groups: dict[str, list] = {}
    for r, inp in _usable(campaign, map, verdict=verdict):
        groups.setdefault(inp, []).append(r)
    if not groups:
        raise ConfigError(f"{campaign.path}: no usable test point (verdict {verdict}) to identify")
    cases = Path(out_dir) / "cases"
    cases.mkdir(parents=True, exist_ok=True)
    paths = []
    for inp, rows in groups.items():
        points = [TestPointRef(_mcap_of(campaign, r), r.start_s - pad_s, r.end_s + pad_s,
                               f"flight {r.flight_id} TP{r.number}") for r in rows]
        path = cases / f"{inp}.toml"
        path.write_text(case_text_for_map(points, map=map, inputs=[inp], name=f"campaign-{inp}"))
        paths.append(path)
    return run_batch(paths, Path(out_dir) / "reports", stage="frequency-response", workers=workers,
                     dask_address=dask_address, progress=progress)


def identify_selection(campaign, out_dir, *, map, swept_input: str, verdict: str | None = "usable", axis=None,
                       flight=None, conditions=None, outputs=None, band_rad_s=None, transfer_functions=None,
                       windows_s=None, pad_s: float = TRIM_PAD_S) -> CampaignIdentification:
    """Identify the test points of ``swept_input`` the filters select, concatenated, into ``out_dir``.

    Parameters
    ----------
    campaign : Campaign
    out_dir : str or Path
        Where the case file and the report go.
    map : str, Path or ChannelMap
        The channel map whose signals the flights carry (a preset name or a file).
    swept_input : str
        The input swept (the map's name for it); the identification's only input. A test point
        found offline (an autopilot's SystemID run, no input named) sweeps the input the map's
        ``[test_points] axes`` names for its axis.
    verdict : str or None
        ``"usable"`` (default): GO, or not judged (found offline); ``"GO"``, ``"NO-GO"``, ``"none"``:
        that verdict only; None: any. Runs whose signals the log does not hold are left out.
    axis, flight, conditions
        Filters of :meth:`Campaign.test_points`.
    outputs, band_rad_s, transfer_functions, windows_s
        As :func:`livesweep.campaign.concat.identify_test_points` (defaults: the map's).
    pad_s : float
        Trim taken before and after each test point [s].

    Raises
    ------
    ConfigError
        No test point matches (naming the filters).
    """
    from livesweep.campaign.concat import TestPointRef, identify_test_points
    from livesweep.report.writer import write_report

    rows = [r for r in _usable(campaign, map, verdict=verdict, axis=axis, flight=flight, conditions=conditions)
            if r[1] == swept_input]
    rows = [r for r, _ in rows]
    if not rows:
        raise ConfigError(f"{campaign.path}: no test point of input {swept_input!r} matches (verdict {verdict}, "
                          f"axis {axis}, flight {flight}, conditions {conditions})")
    points = [TestPointRef(_mcap_of(campaign, r), r.start_s - pad_s, r.end_s + pad_s,
                           f"flight {r.flight_id} TP{r.number}") for r in rows]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ident = identify_test_points(points, map=map, inputs=[swept_input], outputs=outputs, band_rad_s=band_rad_s,
                                 transfer_functions=transfer_functions, out_dir=out, windows_s=windows_s,
                                 name=f"campaign-{swept_input}")
    report = write_report(ident, out / "report", plots=True)
    rid = campaign.add_result([r.id for r in rows], "identification",
                              {"report": str(report), "swept_input": swept_input, "test_points": len(rows)},
                              selection={"swept_input": swept_input, "verdict": verdict, "axis": axis,
                                         "flight": flight, "conditions": conditions})
    return CampaignIdentification(ident, report, tuple(rows), rid)
