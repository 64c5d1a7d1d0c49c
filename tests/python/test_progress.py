"""The command line's progress report (core/progress.py): plain lines in a log, at most one every
few seconds within a stage; a bar redrawn in place on a terminal; the time left from the pace."""
import io

from canopy_ao.core.progress import PREFIX, Progress, duration


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_a_log_gets_a_line_per_stage_and_at_most_one_per_interval_within_it():
    out, clock = io.StringIO(), Clock()
    p = Progress(out, interval=5.0, tty=False, clock=clock)
    p.update("preparing")
    p.update("evaluating", "Tree", 0, 1000)
    for k in range(1, 10):  # a step every second: a line at most every 5 s
        clock.t = float(k)
        p.update("evaluating", "Tree", 100 * k, 1000)
    p.update("writing")
    lines = out.getvalue().splitlines()
    assert all(line.startswith(PREFIX) for line in lines)
    assert lines[0] == f"{PREFIX} preparing"
    assert lines[1] == f"{PREFIX} evaluating Tree, 0/1000 receivers (0 %), time left unknown"
    # 5 s after the stage's first line, 500 of 1000 done in 5 s: 5 s left.
    assert lines[2] == f"{PREFIX} evaluating Tree, 500/1000 receivers (50 %), time left 5 s"
    assert lines[-1] == f"{PREFIX} writing"
    assert len(lines) == 4


def test_a_terminal_gets_one_bar_redrawn_in_place_and_cleared_at_the_end():
    out, clock = io.StringIO(), Clock()
    p = Progress(out, tty=True, clock=clock, columns=200)
    p.update("evaluating", "Tree", 0, 400)
    clock.t = 30.0
    p.update("evaluating", "Tree", 100, 400)
    p.close()
    text = out.getvalue()
    assert "\n" not in text  # one line, rewritten
    assert text.count("\r") == 3
    assert "[######..................] evaluating Tree, 100/400 receivers (25 %), " \
           "time left 1 min 30 s" in text
    assert text.endswith("\r\x1b[K")
    # Never wider than the terminal: a wrapped line would not redraw in place.
    narrow = io.StringIO()
    p = Progress(narrow, tty=True, clock=clock, columns=40)
    p.update("evaluating", "Tree", 100, 400)
    assert max(len(part) for part in narrow.getvalue().split("\r\x1b[K")) == 39


def test_durations_read_as_a_person_would_say_them():
    assert [duration(s) for s in (0.4, 42, 185, 3720)] == ["0 s", "42 s", "3 min 05 s",
                                                             "1 h 02 min"]
