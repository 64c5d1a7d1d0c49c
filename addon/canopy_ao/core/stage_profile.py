"""Where a bake's seconds go, stage by stage: on when the environment has CANOPY_AO_PROFILE=1.

The command line (cli.py) then prints, on stderr after the bake, one line per stage::

    canopy_ao: profile: <stage> <seconds> s

in the order a bake meets them: Blender's start and the file's load (the process's age when the
script began; Linux only), the add-on's module imports and registration, the bake's own stages
(BakeJob.timings and the plan's), the native core's (the tracer's checks, corner tables and BVH
build; the rays' sampling, tracing and reduction as the CPU seconds their worker threads ran,
summed: native stage_clock.h), the save, the CPU seconds of the bake and of the process so far
(every thread: steadier than wall time on a shared machine), and last ``process age`` (seconds
since the process started), so a caller timing the whole command sees what Blender's exit
took. bench/stage_profile.py reads these lines. Profiling changes no result.
"""

from __future__ import annotations

import os
import sys
import time

ENV = "CANOPY_AO_PROFILE"
PREFIX = "canopy_ao: profile:"


def enabled() -> bool:
    """Whether CANOPY_AO_PROFILE asks for stage times (set and not 0)."""
    return os.environ.get(ENV, "").strip() not in ("", "0")


def process_age() -> float | None:
    """Seconds since this process started (Linux: /proc, to the kernel's clock tick, 10 ms
    usually), None where that cannot be read."""
    try:
        with open("/proc/self/stat") as f:
            # Field 22 (starttime, in clock ticks since boot) follows the command name, which
            # may hold spaces: count from the last ')'.
            start = int(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            up = float(f.read().split()[0])
        return max(up - start / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return None


class StageLog:
    """Stage name -> seconds, in the order first added (a stage added twice sums)."""

    def __init__(self):
        self.seconds = {}

    def add(self, name: str, seconds: float) -> None:
        self.seconds[name] = self.seconds.get(name, 0.0) + float(seconds)

    def timer(self, name: str):
        """A context manager adding the seconds of its block to ``name``."""
        return _Timer(self, name)

    def add_report(self, rep: dict) -> None:
        """A bake report's stages (job.BakeJob.commit: "stage_seconds", the plan's "timings")."""
        for k, v in (rep.get("stage_seconds") or {}).items():
            self.add(f"bake: {k}", v)
        for k, v in (rep.get("timings") or {}).items():
            self.add(f"plan: {k}", v)

    def add_native(self, native: dict) -> None:
        """take_stage_seconds() of the native module: {name: (seconds, sections)}."""
        for k, (seconds, _count) in native.items():
            self.add(f"native: {k}", seconds)

    def lines(self) -> list[str]:
        return [f"{PREFIX} {k} {v:.4f} s" for k, v in self.seconds.items()]

    def print(self, stream=None) -> None:
        stream = stream if stream is not None else sys.stderr
        age = process_age()
        for line in self.lines():
            print(line, file=stream)
        print(f"{PREFIX} process CPU {time.process_time():.4f} s", file=stream)
        if age is not None:
            print(f"{PREFIX} process age {age:.4f} s", file=stream)
        stream.flush()


class _Timer:
    def __init__(self, log, name):
        self.log, self.name = log, name

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.log.add(self.name, time.perf_counter() - self.t0)
        return False


def parse(text: str) -> dict:
    """{stage: seconds} from the profile lines in ``text`` (a command's stderr)."""
    out = {}
    for line in text.splitlines():
        if line.startswith(PREFIX) and line.endswith(" s"):
            name, _, value = line[len(PREFIX):-2].strip().rpartition(" ")
            try:
                out[name] = float(value)
            except ValueError:
                continue
    return out
