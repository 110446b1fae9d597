"""The machine a benchmark ran on: how much other work was running when it started."""

from __future__ import annotations

import os
import time


def busy_cores(window: float = 1.0) -> float | None:
    """CPU cores kept busy by whatever runs now, from two reads of /proc/stat ``window`` s
    apart (None off Linux). Unlike the 1-minute load average, it does not still count a
    benchmark that finished a minute ago."""

    def read() -> tuple[int, int]:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
        idle = v[3] + (v[4] if len(v) > 4 else 0)
        return sum(v) - idle, sum(v)

    try:
        b0, t0 = read()
        time.sleep(window)
        b1, t1 = read()
    except (OSError, ValueError, IndexError):
        return None
    return (os.cpu_count() or 1) * (b1 - b0) / max(t1 - t0, 1)


def busy_text(busy: float | None) -> str:
    """How busy the machine was, in words, for a benchmark's report."""
    if busy is None:
        return "other work at the start not measured"
    kind = "a shared machine" if busy > 0.5 else "a quiet machine"
    return f"{busy:.2f} cores busy with other work just before the start ({kind})"
