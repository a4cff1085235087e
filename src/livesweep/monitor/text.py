"""Numbers as an operator reads them: percentages, bands, durations and markdown cells.

The one rule that matters here: a value judged against a threshold is never printed on the other
side of it. ``f"{0.5999:.0%}"`` prints ``60%`` next to "NOT adequate (need 60%)"; :func:`percent`
prints ``59.9 %`` instead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from livesweep.numeric import percent, points
from livesweep.spectral.criteria import DEFAULT_CRITERIA

__all__ = ["percent", "band_text", "duration_text", "time_text", "EPOCH_MIN_S", "md_cell", "md_table", "omega_text", "sweep_text",
           "coherence_kind_text", "adequacy_markdown", "markdown_test_points", "test_point_line", "COHERENCE_KINDS",
           "DEFAULT_REQUIRED_FRACTION"]

#: Fraction of the band a required pair must cover (one definition: livesweep.spectral.adequacy).
DEFAULT_REQUIRED_FRACTION = DEFAULT_CRITERIA.required_fraction


def _finite(x) -> bool:
    try:
        return x is not None and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def band_text(band, *, digits: int = 3, missing: str = "—") -> str:
    """``(lo, hi)`` [rad/s] as ``"0.3 – 18.9"``; several bands comma-separated; None or empty as ``missing``."""
    if band is None:
        return missing
    if isinstance(band, str):
        return band or missing
    b = list(band)
    if not b:
        return missing
    if len(b) == 2 and all(_finite(x) for x in b):
        return f"{float(b[0]):.{digits}g} – {float(b[1]):.{digits}g}"
    parts = [band_text(x, digits=digits, missing="") for x in b]
    return ", ".join(p for p in parts if p) or missing


def duration_text(seconds: float | None, *, missing: str = "unknown") -> str:
    """A duration as an operator says it: ``"45 s"``, ``"2 min 05 s"``, ``"1 h 03 min"``."""
    if not _finite(seconds):
        return missing
    s = max(0.0, float(seconds))
    if s < 90.0:
        return f"{s:.0f} s"
    m = int(round(s)) // 60
    if m < 60:
        return f"{m} min {int(round(s)) % 60:02d} s"
    return f"{m // 60} h {m % 60:02d} min"


#: A data time at least this large is seconds since the UNIX epoch (a receive-time map, a vehicle
#: on GPS time), not since boot [s]: 1e8 s is 1973, more than three years of uptime.
EPOCH_MIN_S = 1e8


def time_text(t_s: float | None, *, missing: str = "unknown") -> str:
    """A data time as an operator reads it: ``"123.4 s"`` since boot, or the UTC clock time
    ``"14:46:39.6 UTC"`` for seconds since the UNIX epoch (:data:`EPOCH_MIN_S`)."""
    if not _finite(t_s):
        return missing
    t = float(t_s)
    if abs(t) < EPOCH_MIN_S:
        return f"{t:.1f} s"
    tenths = int(round(t * 10.0))
    sec = (tenths // 10) % 86400
    return f"{sec // 3600:02d}:{sec // 60 % 60:02d}:{sec % 60:02d}.{tenths % 10} UTC"


def md_cell(s) -> str:
    """Text safe in one markdown table cell (pipes escaped, line breaks flattened)."""
    return str(s).replace("\\", "\\\\").replace("|", "\\|").replace("\r", " ").replace("\n", " ")


def md_table(header: Sequence[str], rows: Sequence[Sequence]) -> list[str]:
    """Markdown table lines (every cell through :func:`md_cell`)."""
    out = ["| " + " | ".join(md_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(md_cell(c) for c in r) + " |" for r in rows]
    return out


# --------------------------------------------------------------------------------------------
# What the view writes as text
# --------------------------------------------------------------------------------------------

#: How each coherence kind is named to the operator.
COHERENCE_KINDS = {"ordinary": "ordinary γ² (single input)", "partial": "partial γ² (MISO-conditioned)"}


def coherence_kind_text(kind: str) -> str:
    """``"ordinary γ² (single input)"`` or ``"partial γ² (MISO-conditioned)"``; ValueError otherwise."""
    try:
        return COHERENCE_KINDS[kind]
    except KeyError:
        raise ValueError(f"coherence_kind must be 'ordinary' or 'partial', got {kind!r}") from None


def omega_text(omega_rad_s: float) -> str:
    """A frequency [rad/s] with two significant digits below 10 and none after the point above."""
    w = float(omega_rad_s)
    return f"{w:.0f}" if abs(w) >= 9.95 else f"{w:.2g}"


def sweep_text(name: str, omega_rad_s: float | None, time_remaining_s: float | None) -> str:
    """One input's sweep as a status line.

    ``"da: sweeping 3.2 rad/s, 45 s to the band top"``; ``"da: not sweeping"`` when the frequency
    is unknown (a quiet input); ``"..., band top reached"`` when no time remains; ``"..., time to the
    band top unknown"`` when the monitor cannot tell (the frequency is not rising).
    """
    if not _finite(omega_rad_s):
        return f"{name}: not sweeping"
    head = f"{name}: sweeping {omega_text(omega_rad_s)} rad/s"
    if not _finite(time_remaining_s):
        return head + ", time to the band top unknown"
    if float(time_remaining_s) <= 0.0:
        return head + ", band top reached"
    return f"{head}, {duration_text(time_remaining_s)} to the band top"


def _row_verdict(fraction, band, required: float) -> str:
    if _finite(fraction) and float(fraction) >= required:
        return "adequate"
    return "partly adequate" if band_text(band) != "—" else "not adequate"


def adequacy_markdown(t_s: float, rows: Sequence[dict], verdict: str, reasons: Sequence[str], *,
                      coherence_kind: str = "ordinary", sweep: dict | None = None,
                      required_fraction: float = DEFAULT_REQUIRED_FRACTION, lag_s: float | None = None,
                      min_coherence: float = DEFAULT_CRITERIA.min_coherence) -> str:
    """The status document: verdict, coherence kind, sweep per input, reasons and the adequacy table.

    Parameters
    ----------
    t_s : float
        Flight time of the estimate [s].
    rows : sequence of dict
        ``{"output", "input", "band": (lo, hi) [rad/s] or None, "fraction": 0..1, ["verdict"]}``.
        A row's verdict is ``row["verdict"]`` when given, else "adequate" at or above
        ``required_fraction``, "partly adequate" below it with an adequate band, "not adequate"
        without one.
    verdict : str
        The overall verdict (``GO``/``NO-GO``/``WAIT``).
    reasons : sequence of str
    coherence_kind : str
        ``"ordinary"`` or ``"partial"``: which coherence the verdict judged.
    sweep : dict, optional
        ``{input: (omega [rad/s] or None, time remaining [s] or None)}``.
    required_fraction : float
        Threshold of the row verdicts; fractions are printed with :func:`percent` against it.
    lag_s : float, optional
        How far behind the link the view is [s] (said when it is over a second).
    min_coherence : float
        The coherence threshold of the criteria judging (stated in the status line).
    """
    behind = f"; **{lag_s:.0f} s behind the link**" if _finite(lag_s) and float(lag_s) >= 1.0 else ""
    lines = [f"## {md_cell(verdict)}", ""]
    if reasons:                                  # what the verdict is about, under it
        lines += [f"**{md_cell(reasons[0])}**", ""]
        reasons = reasons[1:]
    lines += [f"Flight time {time_text(t_s)}{behind}. Coherence judged: **{coherence_kind_text(coherence_kind)}**, "
              f"threshold γ² ≥ {min_coherence:g}", ""]
    if sweep:
        lines += [f"- {md_cell(sweep_text(name, *v))}" for name, v in sweep.items()] + [""]
    lines += [f"- {md_cell(r)}" for r in reasons]
    if reasons:
        lines.append("")
    table = []
    for r in rows:
        band, frac = r.get("band"), r.get("fraction")
        v = r.get("verdict") or _row_verdict(frac, band, required_fraction)
        table.append([f"{r.get('output', '?')}/{r.get('input', '?')}", band_text(band),
                      percent(frac, required_fraction), v])
    if table:
        lines += ["Sliding window (what is happening now, not the verdict):", ""]
    lines += md_table(["pair", "adequate band [rad/s]", "fraction", "verdict"], table)
    return "\n".join(lines) + "\n"


def markdown_test_points(entries: Sequence[tuple[int, dict]], t_s: float) -> str:
    """The test-point history: the open test point first, then the others, newest first.

    Parameters
    ----------
    entries : sequence of (number, test-point dict)
        In the order to show. A test-point dict is the monitor's ``/livesweep/test_point`` record:
        ``{"state": "open"|"closed"|..., "start_s", "end_s" (None while open), "source",
        "swept_input", "verdict", "pairs": [{"output", "input", "adequate_fraction",
        "band_rad_s": [lo, hi] or None, "coherence": "ordinary"|"partial"}], "missing": [str, ...]}``
        (optionally ``"required_fraction"`` or ``"criteria"``, default 0.6; ``"label"``, the verdict as shown: "NO-GO
        (link)"; ``"loss_fraction"``, the fraction of its frames lost, said from 0.1 % on).
    t_s : float
        Flight time now [s] (the open test point's elapsed time).
    """
    if not entries:
        return "*No test point yet.*\n"
    out: list[str] = []
    for number, tp in entries:
        out += _tp_section(number, tp, t_s) + [""]
    return "\n".join(out)


def _num(x) -> float | None:
    return float(x) if _finite(x) else None


def _tp_section(number: int, tp: dict, t_s: float) -> list[str]:
    """One test point: a header line, the pair table, then what is still missing (full sentences
    under the table: Rerun's markdown tables do not wrap a long cell, they cut it off)."""
    state = str(tp.get("state") or "?")
    start, end = _num(tp.get("start_s")), _num(tp.get("end_s"))
    swept = tp.get("swept_input") or "input not known"
    if start is None:
        when = "start unknown"
    elif end is None:
        when = f"from {time_text(start)}, {duration_text(float(t_s) - start)} so far"
    else:
        span = (f"{start:.1f} – {end:.1f} s" if max(abs(start), abs(end)) < EPOCH_MIN_S
                else f"{time_text(start)} – {time_text(end)}")
        when = f"{span} ({duration_text(end - start)})"
    head = (f"**Test point {number} ({md_cell(state)}): {md_cell(tp.get('label') or tp.get('verdict') or '?')}**, "
            f"sweeping {md_cell(swept)}, {when}, found by {md_cell(tp.get('source') or '?')}")
    lost = _num(tp.get("loss_fraction"))
    if lost is not None and lost >= 0.0005:        # what rounds to 0.0 % is not said
        head += f"; **{percent(lost)} of its frames lost**"
    required = _required_fraction(tp)
    missing = [str(m) for m in (tp.get("missing") or [])]
    rows, kinds = [], []
    for p in tp.get("pairs") or []:
        label = f"{p.get('output', '?')}/{p.get('input', '?')}"
        frac = p.get("adequate_fraction")
        verdict = "adequate" if _finite(frac) and float(frac) >= required else "NOT adequate"
        n = sum(1 for m in missing if m.startswith(label + " ") or m.startswith(label + ":"))
        kinds.append(str(p.get("coherence") or "ordinary"))
        rows.append([label, band_text(p.get("band_rad_s")), percent(frac, required), verdict,
                     f"{n} below" if n else "—"])
    if kinds:
        kind = kinds[0] if len(set(kinds)) == 1 else None
        head += f"; coherence judged: {kind} γ²" if kind else ""
        if kind is None:     # pairs judged on different kinds: say so per pair
            for r, k in zip(rows, kinds):
                r[0] = f"{r[0]} ({k} γ²)"
    lines = [head, ""]
    if rows:
        lines += md_table(["pair", "adequate band [rad/s]", "fraction", "verdict", "still missing"], rows)
    if missing:
        lines += ["", "Still missing:"] + [f"- {md_cell(m)}" for m in missing]
    return lines


def _required_fraction(tp: dict) -> float:
    """The fraction a test point's pairs had to cover: its ``required_fraction``, else its
    ``criteria``' one, else the method's."""
    required = _num(tp.get("required_fraction"))
    if required is None:
        required = _num((tp.get("criteria") or {}).get("required_fraction"))
    return DEFAULT_REQUIRED_FRACTION if required is None else required


def test_point_line(number: int, tp: dict) -> str:
    """One closed test point in a line: ``"TP1 roll (autopilot, 78.6 s - 128.6 s): GO; p/roll 100 %
    adequate of 3.14 – 75.4 rad/s (+40 points)"``, what its data lost ("27 % of its frames lost")
    and what a NO-GO still needs."""
    start, end = _num(tp.get("start_s")), _num(tp.get("end_s"))
    span = f"{time_text(start)} - {time_text(end)}" if start is not None and end is not None else "?"
    head = f"TP{number} {tp.get('swept_input') or '?'} ({tp.get('source', '?')}, {span}): {tp.get('label') or tp.get('verdict')}"
    band = tp.get("judged_band_rad_s")
    required = _required_fraction(tp)
    parts = []
    for p in tp.get("pairs") or []:
        frac = p.get("adequate_fraction")
        if _finite(frac):
            where = f" of {band_text(band)} rad/s" if band else ""
            parts.append(f"{p.get('output')}/{p.get('input')} {percent(frac, required)} adequate{where} "
                         f"({points(frac, required)})")
    line = head + ("; " + ", ".join(parts) if parts else "")
    lost = _num(tp.get("loss_fraction"))
    if lost is not None and lost >= 0.0005:        # what rounds to 0.0 % is not said
        line += f"; {percent(lost)} of its frames lost"
    if tp.get("verdict") != "GO" and tp.get("missing"):
        line += "; needs: " + "; ".join(str(m) for m in tp["missing"][:3])
    return line
