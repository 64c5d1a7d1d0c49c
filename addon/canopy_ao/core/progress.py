"""Progress of a blocking bake on a stream, and Ctrl-C as a request to stop (the command line).

A terminal (the stream is a tty) gets one bar redrawn in place; a log gets plain lines, one when
the stage changes (gathering, preparing, evaluating, writing) and otherwise at most one every
``interval`` seconds. The time left is the evaluation's pace so far applied to the receivers
left (receivers of one bake cost about the same), so it is given once some are done.
"""

import os
import shutil
import signal
import sys
import time

PREFIX = "canopy_ao: progress:"


class Cancelled(Exception):
    """The user asked the bake to stop (Ctrl-C); nothing was kept."""


def duration(seconds: float) -> str:
    """'42 s', '3 min 05 s', '1 h 02 min'."""
    s = int(round(max(seconds, 0.0)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class Progress:
    """Report a bake's progress on ``stream`` (stderr by default).

    update(stage, name, done, total) with done/total receivers of the whole bake (0/0 outside
    the evaluation). ``clock`` is time.monotonic unless a test gives its own; ``columns``, the
    terminal's width (a bar longer than it would wrap and not redraw in place)."""

    def __init__(self, stream=None, interval=5.0, tty=None, clock=time.monotonic,
                 columns=None):
        self.stream = stream if stream is not None else sys.stderr
        if tty is None:
            isatty = getattr(self.stream, "isatty", None)
            tty = bool(isatty and isatty())
        self.tty, self.interval, self.clock = tty, float(interval), clock
        self.columns = columns or shutil.get_terminal_size((80, 24)).columns
        self._stage = None
        self._last = None  # clock of the last line (log) or redraw (tty)
        self._eval_start = None  # (clock, done) when the evaluation began
        self._drawn = False

    def text(self, stage, name, done, total, unit="receivers"):
        """The progress line: stage, object, share of the receivers (or frames, ...) done and
        the time left."""
        parts = [stage + (f" {name}" if name else "")]
        if total > 0:
            parts.append(f"{done}/{total} {unit} ({100.0 * done / total:.0f} %)")
            left = self.seconds_left(done, total)
            parts.append("time left " + (duration(left) if left is not None else "unknown"))
        return ", ".join(parts)

    def seconds_left(self, done, total):
        """The evaluation's pace so far over the receivers left; None before any is done."""
        if self._eval_start is None:
            return None
        t0, d0 = self._eval_start
        if done <= d0:
            return None
        return (self.clock() - t0) * (total - done) / (done - d0)

    def update(self, stage, name="", done=0, total=0, unit="receivers"):
        now = self.clock()
        if total > 0 and self._eval_start is None:
            self._eval_start = (now, done)
        new_stage = stage != self._stage
        self._stage = stage
        text = self.text(stage, name, done, total, unit)
        if self.tty:
            if not new_stage and self._last is not None and now - self._last < 0.1:
                return
            width = 24
            filled = int(width * done / total) if total > 0 else 0
            bar = f"[{'#' * filled}{'.' * (width - filled)}] " if total > 0 else ""
            line = f"{PREFIX} {bar}{text}"
            self.stream.write("\r\x1b[K" + line[:max(self.columns - 1, 20)])
            self._drawn = True
        else:
            if not new_stage and self._last is not None and now - self._last < self.interval:
                return
            self.stream.write(f"{PREFIX} {text}\n")
        self._last = now
        self.stream.flush()

    def close(self):
        """End the bar's line (a terminal), so what follows starts on its own line."""
        if self.tty and self._drawn:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._drawn = False


class Interrupt:
    """While entered, the first SIGINT (Ctrl-C) only sets ``requested``, which the bake polls
    between steps (check() raises Cancelled); a second one stops the process at once. Left
    with SIGINT's default action when the handler before was not Python's (Blender's own)."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def _handler(self, signum, frame):
        if self.requested:  # asked twice: the user wants out now
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            raise KeyboardInterrupt
        self.requested = True
        # os.write, not sys.stderr: the signal may arrive while the main thread is inside
        # sys.stderr's own write (a progress line), and its buffered writer is not reentrant.
        try:
            os.write(2, b"\ncanopy_ao: stopping after the current step (Ctrl-C again to quit "
                        b"at once)\n")
        except OSError:
            pass

    def check(self):
        if self.requested:
            raise Cancelled("cancelled (Ctrl-C): nothing was written or saved")

    def __enter__(self):
        self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc):
        previous = self._previous if self._previous is not None else signal.SIG_DFL
        signal.signal(signal.SIGINT, previous)
        return False
