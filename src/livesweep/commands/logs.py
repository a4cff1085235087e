"""The log commands: ``convert`` (any log to MCAP), ``inspect`` (what a log holds), ``new-case``
(a case file for a log), ``recover`` (a finished copy of a damaged recording) and ``maps`` (the
channel-map presets)."""

from __future__ import annotations

from pathlib import Path

from livesweep.commands.common import counts_text

__all__ = ["cmd_convert", "cmd_inspect", "cmd_new_case", "cmd_recover", "cmd_maps", "EXIT_DATA_LOST"]


def cmd_inspect(args) -> int:
    """``livesweep inspect LOG``: topics, fields, rates, span, test points, fitting channel maps."""
    from livesweep.inspection import format_inspection, inspect_log, stderr_progress

    print(format_inspection(inspect_log(args.log, columns=args.columns, progress=stderr_progress(args.log))))
    return 0


def cmd_new_case(args) -> int:
    """``livesweep new-case LOG --map NAME``: an annotated case file."""
    from livesweep.new_case import write_new_case

    r = write_new_case(args.log, args.map, args.out, force=args.force)
    if r["converted"]:
        print(f"new-case: converted {args.log} to {r['log']}")
    print(f"new-case: wrote {r['case']} (log {r['log']}, map {args.map}); next: edit [case] and [spectral], then\n"
          f"  livesweep identify {r['case']} --out report")
    return 0


#: Exit status of ``livesweep recover`` when messages (or other records) were lost or are kept
#: unverified: the finished copy is still written.
EXIT_DATA_LOST = 1


def cmd_recover(args) -> int:
    """``livesweep recover LOG``: a finished copy of an unfinished or damaged recording, saying what
    was lost or kept unverified; exit status 0 only when nothing was."""
    from livesweep.telemetry.mcap_recover import RECOVER_METADATA_NAME, recover

    most = 10                                # offsets, ranges and lines printed before "... and N more"

    def listed(items, fmt=str) -> str:
        return ", ".join(fmt(x) for x in items[:most]) + (f" and {len(items) - most} more" if len(items) > most else "")

    def count(n: int, what: str) -> str:
        return f"{n} {what}" + ("" if n == 1 else "s")

    src = Path(args.log)
    out = Path(args.out) if args.out else src.with_name(src.stem + ".recovered.mcap")
    from livesweep.locks import check_file_free

    check_file_free(out, overwrite=args.force)
    r = recover(src, out, overwrite=args.force)
    state = ("was finished" if r.complete_source
             else "was unfinished (no readable footer: its writer stopped before closing it, or its end is damaged)")
    of = f" of the {r.messages_expected} it holds" if r.messages_expected is not None else ""
    print(f"recover: {src} {state}; {count(r.messages_written, 'message')}{of} written to {out}, a finished "
          "file any MCAP reader opens")
    if r.messages_lost is None:
        print("recover: LOST: an unknown number of messages (no readable statistics record or message index "
              "counts them)")
    elif r.messages_lost:
        print(f"recover: LOST: {count(r.messages_lost, 'message')}" + (f" of {r.messages_expected}" if of else ""))
    if r.damaged_chunks:
        print(f"recover:   skipped {count(len(r.damaged_chunks), 'chunk')} that did not decompress, at bytes "
              f"{listed(r.damaged_chunks)}")
    if r.skipped_bytes:
        total = sum(b - a for a, b in r.skipped_bytes)
        print(f"recover:   {total} bytes not read: {listed(r.skipped_bytes, lambda ab: f'{ab[0]}-{ab[1]}')}")
    if r.messages_unverified:
        where = (f"{count(len(r.unverified_chunks), 'chunk')} failing the CRC check (at bytes "
                 f"{listed(r.unverified_chunks)})" if r.unverified_chunks
                 else "outside chunks in a data section that fails its CRC check")
        print(f"recover: UNVERIFIED: {count(r.messages_unverified, 'message')} kept from {where}: their contents "
              f"may differ from what was recorded; {out} records this in its {RECOVER_METADATA_NAME!r} metadata")
    for line in r.unreadable[:most]:
        print(f"recover:   {line}")
    if len(r.unreadable) > most:
        print(f"recover:   ... and {len(r.unreadable) - most} more")
    for line in r.notes[:most]:
        print(f"recover: note: {line}")
    if len(r.notes) > most:
        print(f"recover: note: ... and {len(r.notes) - most} more")
    if not r.clean:
        return EXIT_DATA_LOST
    print("recover: nothing that was in the file was lost, and every message is verified")
    return 0

def cmd_maps(args) -> int:
    """List the channel-map presets: name, description, inputs and outputs, what each needs."""
    from livesweep.maps import list_maps

    for m in list_maps():
        print(m.name)
        print(f"    {m.description}")
        print(f"    inputs: {', '.join(m.inputs)}; outputs: {', '.join(m.outputs)}")
        print(f"    needs: {m.needs}")
    print("use one with: livesweep monitor --map NAME ... / livesweep replay LOG --map NAME")
    return 0


def cmd_convert(args) -> int:
    """Convert a log to MCAP and print what was read, skipped and repaired."""
    from livesweep.convert import convert

    options = {"column_map": args.columns} if args.columns else {}
    if args.partial:
        options["partial"] = True
    res = convert(args.src, args.out, force=args.force, **options)
    print(f"{res.source.name} ({res.format}{', ' + res.format_version if res.format_version else ''}) -> {res.output}")
    print(f"  messages read {res.messages_read}, written {res.messages_written} on {len(res.topics)} channels")
    print(f"  skipped: {counts_text(res.skipped)}; repaired: {counts_text(res.repaired)}")
    for w in res.warnings:
        print(f"  warning: {w}")
    return 0
