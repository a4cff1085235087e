"""The summary ``livesweep monitor``, ``replay`` and ``demo`` print when the monitor stops: frames,
estimates, repairs, what each source received, rejected and lost, the test points, the verdict
and what was recorded."""

from __future__ import annotations

import sys

from livesweep.commands.common import counts_text

__all__ = ["print_monitor_summary", "ALIGNER_WORDS"]

#: How the monitor's summary names the aligner's counts of what it repaired or left out: (one, many).
ALIGNER_WORDS = {
    "missing_field": ("frame lacking a mapped field", "frames lacking a mapped field"),
    "not_a_number": ("value that was not a number", "values that were not numbers"),
    "late_dropped": ("late sample dropped", "late samples dropped"),
    "reordered": ("sample put back in time order", "samples put back in time order"),
    "wraps": ("clock wrap unwrapped", "clock wraps unwrapped"),
    "resets": ("clock reset", "clock resets"),
    "clock_rejected": ("sample with an implausible stamp dropped", "samples with an implausible stamp dropped"),
    "other_system": ("frame of another system left out", "frames of another system left out"),
    "samples_skipped": ("grid sample skipped at a clock jump", "grid samples skipped at a clock jump"),
    "samples_invalid": ("grid sample left invalid in a gap (not interpolated)",
                        "grid samples left invalid in gaps (not interpolated)"),
}


def _loss_text(src: dict) -> str:
    """What a source lost, each kind by its own name: the kernel's drops (counted by the kernel),
    MAVLink sequence gaps (an estimate), datagrams recorded but not decoded at the stop."""
    parts = []
    if src.get("kernel_drops"):
        parts.append(f"{src['kernel_drops']} dropped by the kernel (socket buffer full; counted by the kernel)")
    gaps = sum((src.get("seq_gaps") or {}).values())
    if gaps:
        parts.append(f"{gaps} missing by MAVLink's 8-bit sequence (an estimate: frames refused here and losses "
                     "before this link count too; runs of 256 are not seen)")
    if src.get("undecoded_at_stop"):
        parts.append(f"{src['undecoded_at_stop']} recorded as received but not decoded at the stop "
                     "(/link/mavlink holds them)")
    return "loss: " + "; ".join(parts) if parts else ""


def model_lines(model: dict | None) -> list[str]:
    """A test point's ``/livesweep/model`` record in lines: per pair its structure, each parameter
    with its bound, J and the flags; then each limit it broke."""
    if not model:
        return []
    out = []
    for p in model["pairs"]:
        params = ", ".join(f"{q['name']} {q['value']:.4g}" + ("" if q["cramer_rao"] is None else f" ± {q['cramer_rao']:.2g}")
                           + (f" {q['units']}" if q["units"] else "") for q in p["parameters"] if q["value"] is not None)
        cost = "" if p["cost"] is None else f"; J {p['cost']:.3g}"
        flags = f"; not to trust: {'; '.join(p['flags'])}" if p["flags"] else ""
        out.append(f"model {p['name']} ({p['structure']}): {params}{cost}{flags}")
    out += [f"LIMIT: {b}" for b in model["breaches"]]
    return out


def print_monitor_summary(summary: dict, out=None) -> None:
    """Print the summary of a monitor run (:meth:`livesweep.Monitor.stop`, :attr:`livesweep.ReplayResult.summary`)."""
    from livesweep.monitor.pipeline import LINK_ANOMALIES

    out = sys.stdout if out is None else out
    anomaly_words = {key: words for where, key, words in LINK_ANOMALIES if where == "source"}
    anomaly_keys = set(anomaly_words)
    print(f"monitor: {summary['frames']} frames, {summary['estimates']} estimates over {summary['data_s'] or 0:.1f} s "
          f"of data in {summary['wall_s']:.1f} s", file=out)
    al = summary["aligner"]
    issues = {k: v for k, v in al.items() if k in ("missing_field", "not_a_number", "late_dropped", "reordered",
                                                   "wraps", "resets", "clock_rejected", "other_system",
                                                   "samples_skipped", "samples_invalid") and v}
    if issues:
        print(f"  repairs and gaps: {counts_text(issues, ALIGNER_WORDS)}", file=out)
    counters = summary.get("counters") or {}
    for src in counters.get("sources", []):
        received = src.get("received") or src.get("replayed") or {}
        systems = src.get("by_system") or {}
        bad = {k: v for k, v in src.items() if k in anomaly_keys and k != "kernel_drops" and v}
        by_sys = sorted(systems.items(), key=lambda kv: -kv[1])
        sys_text = ", ".join(f"{k}: {v}" for k, v in by_sys[:5]) + (f", ... ({len(by_sys)} systems)" if len(by_sys) > 5
                                                                     else "")
        rejected = f"; rejected or repaired: {counts_text(bad, anomaly_words)}" if bad else "; nothing rejected"
        print(f"  {src['name']}: {sum(received.values())} frames" + (f" from systems {{{sys_text}}}"
              if systems else "") + rejected, file=out)
        loss = _loss_text(src)
        if loss:
            print(f"    {loss}", file=out)
    pipe = counters.get("pipeline") or {}
    if pipe.get("not_taken_at_stop"):
        print(f"  not recorded: {pipe['not_taken_at_stop']} frames a source still held when the stop's drain "
              "time was up", file=out)
    if pipe.get("analysis_shed"):
        print(f"  analysis skipped {pipe['analysis_shed']} frames to keep up (all recorded)", file=out)
    from livesweep.monitor.text import test_point_line

    tps = summary.get("test_points") or []
    print(f"  test points: {len(tps)}" + ("" if tps else " (no sweep, SystemID run or marker seen)"), file=out)
    models = {m["test_point"]["number"]: m for m in summary.get("models") or ()}
    for k, tp in enumerate(tps, 1):
        print(f"    {test_point_line(k, tp)}", file=out)
        for line in model_lines(models.get(k)):
            print(f"      {line}", file=out)
        nxt = tp.get("next")
        if nxt and nxt.get("needed"):
            for line in nxt["lines"]:
                print(f"      next: {line}", file=out)
    if summary["verdict"]:
        print(f"  verdict: {summary['verdict']}", file=out)
    for line in summary.get("map_problems") or ():
        print(f"  map: {line}", file=out)
    if summary.get("recorded"):
        from livesweep.telemetry.recorder import RAW_TOPIC, RESULT_PREFIX

        rec = summary["recorded"]
        raw = rec.get(RAW_TOPIC, 0)
        results = sum(n for t, n in rec.items() if t.startswith(RESULT_PREFIX + "/"))
        print(f"  recorded {sum(rec.values())} messages: {sum(rec.values()) - raw - results} received"
              + (f", {raw} datagrams as received" if raw else "") + f", {results} live results", file=out)

