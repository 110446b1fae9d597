"""The server's share of key-to-screen: from a changed command to the pose frame it moves.

Runs one `serve` operator driver in-process on the `serve --demo` inputs (reach-pillar,
informed mode: the live scorer runs every step) with an outbox that timestamps every pose
frame, starts an episode and changes the command (dy +1 / -1 in turn) every 200–250 ms, at
a random phase of the 50 ms control step, as a person's key presses are. Reports p50 / p95
of command → next pose frame sent, with the driver's early step (a changed command pulls the
next step forward by up to half a period) and without it (``--earliest 0``: the step waits
for its grid), in alternating runs, with the load average beside each. No browser and no
socket: what is left is the wait for the step, the step and the frame's packing.

Run: ``python benchmarks/bench_step_wait.py [--presses 60] [--runs 2] [--demo-dir DIR]
[--out FILE.md]``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


class _Outbox:
    def __init__(self) -> None:
        self.frames: list[float] = []

    def send(self, message: str | bytes, droppable: bool = False) -> None:
        if isinstance(message, bytes):
            self.frames.append(time.perf_counter())


def measure(earliest: float, presses: int, demo_dir: Path, out: Path) -> list[float]:
    """Command-to-frame latencies (ms) of ``presses`` changed commands."""
    from rich.console import Console

    import elicit_jax.web.driver as driver_module
    from elicit_jax.compat.thresholds import read_thresholds
    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.pipeline.serve_demo import DemoRecipe, demo_inputs
    from elicit_jax.web.protocol import Message

    driver_module.EARLIEST = earliest
    demo = demo_inputs(DemoRecipe(), demo_dir, echo=lambda _: None, console=Console(quiet=True))
    config = SessionConfig(
        task="reach-pillar",
        policy=str(demo.policy),
        base_demos=str(demo.base_demos),
        thresholds=read_thresholds(demo.thresholds),
        operator="browser:op",
        practice=0,
        prompt=0,
        demos=1,
        max_episodes=3,
        horizon=100_000,
    )
    outbox = _Outbox()
    d = driver_module.OperatorDriver("op", config, out, log=lambda _: None)
    d.attach(outbox)
    d.start()
    try:
        deadline = time.monotonic() + 300
        while d.state != "ready" and time.monotonic() < deadline:
            time.sleep(0.05)
        if d.state != "ready":
            raise SystemExit(f"the driver did not open: {d.state} {d.message}")
        d.handle(Message("action", action=(0.0, 0, 0, 0, 0, 0, -1.0)))
        d.handle(Message("start"))
        time.sleep(1.0)
        lat = []
        for i in range(presses):
            time.sleep(0.2 + random.random() * 0.05)
            n, t = len(outbox.frames), time.perf_counter()
            d.handle(Message("action", action=(0.0, (-1.0) ** i, 0, 0, 0, 0, -1.0)))
            while len(outbox.frames) <= n:
                time.sleep(0.0005)
            lat.append(1e3 * (outbox.frames[n] - t))
        return lat
    finally:
        d.stop()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--presses", type=int, default=60)
    p.add_argument("--runs", type=int, default=2, help="alternating runs of each setting")
    p.add_argument("--demo-dir", type=Path, default=None, help="serve --demo's cache root")
    p.add_argument("--out", type=Path, default=None, help="append a Markdown section here")
    a = p.parse_args()
    from elicit_jax.pipeline.serve_demo import default_demo_root

    demo_dir = a.demo_dir or default_demo_root()
    command = "python benchmarks/bench_step_wait.py " + " ".join(sys.argv[1:])
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-step-wait-") as tmp:
        for run in range(a.runs):
            for earliest in (0.5, 0.0):
                load0 = os.getloadavg()[0]
                lat = measure(earliest, a.presses, demo_dir, Path(tmp) / f"r{run}-{earliest}")
                load1 = os.getloadavg()[0]
                p50, p95 = np.percentile(lat, [50, 95])
                rows.append(
                    f"| {'early step (half a period)' if earliest else 'on the grid (before)'} "
                    f"| {run + 1} | {len(lat)} | {p50:.1f} ms | {p95:.1f} ms | {max(lat):.1f} ms "
                    f"| {load0:.1f}, {load1:.1f} |"
                )
    text = "\n".join(
        [
            "## The server's share: changed command → pose frame (bench_step_wait.py)",
            "",
            f"{dt.datetime.now().isoformat(timespec='seconds')} on {platform.node()} "
            f"({os.cpu_count()} CPUs); `{command.strip()}`.",
            "",
            "| step | run | commands | p50 | p95 | max | load average (1 min) before, after |",
            "|---|---|---|---|---|---|---|",
            *rows,
            "",
        ]
    )
    print(text)
    if a.out:
        with a.out.open("a") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
