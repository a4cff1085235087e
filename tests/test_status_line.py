"""The one-line terminal status: its text, its rate, and how it writes to a terminal or a file."""

from __future__ import annotations

import io

from livesweep.monitor.status_line import StatusLine, format_status

FULL = {"frames_per_s": 512.4, "frames_lost": 3, "test_point": "TP2 da", "test_point_elapsed_s": 102.6,
        "verdict": "NO-GO", "sweep": {"da": 3.24, "dr": None}, "alerts": 1}


def test_format_status_full_and_empty():
    assert format_status(FULL) == "512 fr/s | lost 3 | TP2 da 01:42 | NO-GO | da 3.2 rad/s, dr quiet | 1 alert"
    assert format_status({}) == "- fr/s | lost - | no test point | -"
    long = dict(FULL, test_point_elapsed_s=3 * 3600 + 5, alerts=12, sweep={"da": 15.3})
    assert format_status(long) == "512 fr/s | lost 3 | TP2 da 3:00:05 | NO-GO | da 15 rad/s | 12 alerts"
    cut = format_status(FULL, width=30)
    assert len(cut) == 30 and cut.endswith("…") and cut.startswith("512 fr/s | lost 3")
    assert "\n" not in format_status(dict(FULL, verdict="GO\nNO"))


class _Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_plain_stream_gets_one_line_per_second():
    out, clock = io.StringIO(), _Clock()
    sl = StatusLine(out, clock=clock)
    assert sl.tty is False                                    # a StringIO is no terminal
    assert sl.update(FULL)
    clock.t += 0.4
    assert not sl.update(dict(FULL, verdict="GO"))            # too soon: kept
    clock.t += 0.7
    assert sl.update(dict(FULL, verdict="WAIT"))
    clock.t += 0.1
    assert not sl.update(dict(FULL, alerts=2))
    sl.close()                                                # the pending update is not lost
    lines = out.getvalue().split("\n")
    assert lines[-1] == "" and "\r" not in out.getvalue()
    assert [ln.split(" | ")[3] for ln in lines[:-1]] == ["NO-GO", "WAIT", "NO-GO"]
    assert lines[2].endswith("2 alerts")


def test_terminal_overwrites_with_carriage_return():
    out, clock = io.StringIO(), _Clock()
    sl = StatusLine(out, tty=True, width=200, clock=clock)
    sl.update(dict(FULL, alerts=12))
    clock.t += 1.0
    sl.update(dict(FULL, alerts=1))                           # shorter: the rest of the old line is blanked
    sl.close()
    first = format_status(dict(FULL, alerts=12))
    second = format_status(dict(FULL, alerts=1))
    assert out.getvalue() == "\r" + first + "\r" + second + " " * (len(first) - len(second)) + "\n"


def test_a_broken_stream_does_not_raise():
    out = io.StringIO()
    sl = StatusLine(out, tty=True, width=80)
    out.close()
    assert sl.update(FULL) is True
    sl.close()
