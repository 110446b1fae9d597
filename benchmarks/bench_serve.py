"""Load on `elicit-jax serve`: N simulated operators at the control rate, frame pacing per client.

Starts `elicit-jax serve --demo` (reach-pillar; informed mode, so every step runs the live
scorer; no practice or prompt) on 127.0.0.1 in a subprocess, then for N = 1, 4, 8, 16
connects N WebSocket clients, each a simulated operator: it says hello, starts each episode,
sends an action message every control period (50 ms), and records when each pose frame
arrives. Reported per N: the p50 / p99 / max interval between consecutive frames of the same
episode at each client (episode boundaries, where the operator decides when to go on, are
left out), the share of intervals over 1.5x the control period, and the server's CPU use
(its process's CPU seconds over the window; 200% = both cores).

Reference, in the same run: a bare ticker on the same stack (Starlette on uvicorn, same
frame size, one asyncio task per client sleeping to the next 50 ms deadline, no physics or
scoring) — the pacing this machine allows at all, which separates scheduler jitter from our
work. Target: 8 operators with p99 interval <= 1.5x the control period (75 ms).

Bounded: each level runs --duration seconds after its sessions are open (default 15 s); the
whole run is a few minutes. Loopback only; every process it starts is stopped at the end.

Run: ``python benchmarks/bench_serve.py [--quick] [--out benchmarks/results/serve.md]``.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime as dt
import json
import math
import os
import platform
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import busy_cores, busy_text

PERIOD = 0.05
FRAME_BYTES = 16 + 5 * 7 * 4


def _args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--levels", default="1,4,8,16", help="operators at once, comma-separated")
    p.add_argument("--duration", type=float, default=15.0, help="seconds measured per level")
    p.add_argument("--quick", action="store_true", help="levels 1,8 for 6 s each")
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/serve.md"))
    p.add_argument("--reference-server", type=int, default=None, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.quick:
        a.levels, a.duration = "1,8", 6.0
    return a


# --- the reference: a bare paced ticker on the same stack ------------------------------------
def reference_app():
    """Starlette app: each WebSocket gets a FRAME_BYTES frame every PERIOD, nothing else."""
    from starlette.applications import Starlette
    from starlette.routing import WebSocketRoute

    async def ticker(ws):
        await ws.accept()
        await ws.receive_text()  # hello
        frame = bytes(FRAME_BYTES)

        async def drain():
            while True:
                msg = await ws.receive()
                if msg["type"] == "websocket.disconnect":
                    return

        reader = asyncio.create_task(drain())  # actions and "start" are read and dropped
        await ws.send_text(json.dumps({"type": "state", "state": "ready", "review_pending": False}))
        step, t = 0, time.perf_counter()
        try:
            while not reader.done():
                t += PERIOD
                await asyncio.sleep(max(0.0, t - time.perf_counter()))
                step += 1
                head = bytes([1, 1]) + (5).to_bytes(2, "little") + (0).to_bytes(4, "little")
                await ws.send_bytes(head + step.to_bytes(4, "little") + frame[12:])
        except Exception:
            pass

    return Starlette(routes=[WebSocketRoute("/ws", ticker)])


def run_reference_server(port: int) -> None:
    import uvicorn

    from elicit_jax.web.serve import bind

    sock = bind("127.0.0.1", port)
    print(f"open http://127.0.0.1:{sock.getsockname()[1]}/", flush=True)
    config = uvicorn.Config(reference_app(), log_level="warning", ws_per_message_deflate=False)
    uvicorn.Server(config).run(sockets=[sock])


# --- servers ---------------------------------------------------------------------------------
def start_server(cmd: list[str], timeout: float = 600.0) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.time() + timeout
    lines = []
    while time.time() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        m = re.search(r"open (http://\S+)", line)
        if m:
            return proc, m.group(1)
    proc.kill()
    raise SystemExit("the server did not start:\n" + "".join(lines))


def stop_server(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of a process (all its threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# --- simulated operators ---------------------------------------------------------------------
async def operator(
    url: str, name: str, ready: asyncio.Event, stop: asyncio.Event, out: dict
) -> None:
    """One operator: start episodes, an action every PERIOD, record frame arrival intervals."""
    import websockets

    intervals: list[float] = []
    finals: list[int] = []
    frames = 0
    async with websockets.connect(url, max_size=2**22, compression=None) as ws:
        await ws.send(json.dumps({"type": "hello", "name": name}))
        last: tuple[int, int, float] | None = None
        running = False
        t0 = time.perf_counter()

        async def act():
            k = 0
            while not stop.is_set():
                k += 1
                a = [math.sin(0.1 * k), math.cos(0.13 * k), 0.3 * math.sin(0.05 * k), 0, 0, 0, -1]
                try:
                    await ws.send(json.dumps({"type": "action", "a": [round(x, 3) for x in a]}))
                except Exception:
                    return
                await asyncio.sleep(PERIOD)

        actor = asyncio.create_task(act())
        try:
            while not stop.is_set():
                try:
                    msg = await asyncio.wait_for(ws.recv(), 2.0)
                except TimeoutError:
                    continue
                now = time.perf_counter()
                if isinstance(msg, str):
                    m = json.loads(msg)
                    ending = m.get("type") == "event" and m["event"]["kind"] == "episode-end"
                    if ending and last is not None and intervals and out["measuring"]:
                        finals.append(len(intervals) - 1)  # that frame waited for the verdict
                    if m.get("type") == "state" and m.get("state") == "ready":
                        ready.set()
                        running = True
                        last = None
                        await ws.send(json.dumps({"type": "start"}))
                    elif m.get("type") == "state" and m.get("state") == "error":
                        raise SystemExit(f"operator {name}: {m.get('message')}")
                    continue
                if msg[0] != 1 or not running:
                    continue
                episode = int.from_bytes(msg[4:8], "little")
                step = int.from_bytes(msg[8:12], "little")
                if out["measuring"]:
                    frames += 1
                    if last is not None and last[0] == episode and step == last[1] + 1:
                        intervals.append(now - last[2])
                last = (episode, step, now)
        finally:
            actor.cancel()
    out["clients"].append(
        {
            "name": name,
            "intervals": intervals,
            "finals": finals,
            "frames": frames,
            "seconds": time.perf_counter() - t0,
        }
    )


async def run_level(url: str, n: int, duration: float, pid: int, tag: str) -> dict:
    ws_url = url.replace("http://", "ws://").split("?")[0].rstrip("/") + "/ws"
    stop = asyncio.Event()
    out: dict = {"clients": [], "measuring": False}
    readies = [asyncio.Event() for _ in range(n)]
    tasks = [
        asyncio.create_task(operator(ws_url, f"{tag}{n}-{i}", readies[i], stop, out))
        for i in range(n)
    ]
    t_open = time.perf_counter()
    while not all(r.is_set() for r in readies):  # every session open (or a client failed)
        failed = [t for t in tasks if t.done()]
        if failed:
            stop.set()
            failed[0].result()
            raise SystemExit("a simulated operator stopped before its session opened")
        if time.perf_counter() - t_open > 900:
            raise SystemExit("the sessions did not open within 900 s")
        await asyncio.sleep(0.2)
    opened = time.perf_counter() - t_open
    await asyncio.sleep(2.0)  # warm-up
    load0 = os.getloadavg()[0]
    cpu0, wall0 = cpu_seconds(pid), time.perf_counter()
    out["measuring"] = True
    await asyncio.sleep(duration)
    out["measuring"] = False
    cpu1, wall1 = cpu_seconds(pid), time.perf_counter()
    stop.set()
    await asyncio.gather(*tasks, return_exceptions=True)
    return summarize(
        out["clients"],
        n,
        100 * (cpu1 - cpu0) / (wall1 - wall0),
        opened,
        (load0, os.getloadavg()[0]),
    )


def summarize(clients: list[dict], n: int, cpu: float, opened: float, load) -> dict:
    import numpy as np

    iv = np.concatenate([np.asarray(c["intervals"]) for c in clients]) * 1e3
    within = (
        np.concatenate([np.delete(np.asarray(c["intervals"]), c["finals"]) for c in clients]) * 1e3
    )
    per_client_p99 = [
        float(np.percentile(c["intervals"], 99)) * 1e3 for c in clients if len(c["intervals"])
    ]
    return {
        "operators": n,
        "intervals": int(iv.size),
        "p50_ms": float(np.percentile(iv, 50)),
        "p99_ms": float(np.percentile(iv, 99)),
        "p99_not_final_ms": float(np.percentile(within, 99)),
        "finals": int(iv.size - within.size),
        "max_ms": float(iv.max()),
        "over_1_5x": float(np.mean(iv > 1.5 * PERIOD * 1e3)),
        "worst_client_p99_ms": max(per_client_p99),
        "fps_per_client": float(np.mean([c["frames"] for c in clients])) / 1.0,
        "server_cpu_pct": cpu,
        "open_s": opened,
        "load": load,
    }


async def measure(url: str, pid: int, levels: list[int], duration: float, tag: str) -> list:
    rows = []
    for n in levels:
        row = await run_level(url, n, duration, pid, tag)
        row["fps_per_client"] /= duration
        rows.append(row)
        print(
            f"  {tag} N={n}: p50 {row['p50_ms']:.1f} ms, p99 {row['p99_ms']:.1f} ms, "
            f"max {row['max_ms']:.0f} ms, {100 * row['over_1_5x']:.2f}% > 75 ms, "
            f"server CPU {row['server_cpu_pct']:.0f}%, load {row['load'][0]:.1f}",
            flush=True,
        )
    return rows


def _table(rows: list[dict]) -> list[str]:
    out = [
        "| operators | p50 interval | p99 interval | p99 without episodes' last frames "
        "| worst client's p99 | max | > 1.5x period | frames/s per client | server CPU "
        "| load (before, after) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = r["p99_ms"] / (PERIOD * 1e3)
        out.append(
            f"| {r['operators']} | {r['p50_ms']:.1f} ms | {r['p99_ms']:.1f} ms ({ratio:.2f}x) "
            f"| {r['p99_not_final_ms']:.1f} ms ({r['finals']} left out) "
            f"| {r['worst_client_p99_ms']:.1f} ms | {r['max_ms']:.0f} ms "
            f"| {100 * r['over_1_5x']:.2f}% | {r['fps_per_client']:.1f} "
            f"| {r['server_cpu_pct']:.0f}% | {r['load'][0]:.1f}, {r['load'][1]:.1f} |"
        )
    return out


def write_report(path: Path, ours: list[dict], ref: list[dict], args, started: float) -> None:
    at8 = next((r for r in ours if r["operators"] == 8), None)
    verdict = (
        "not measured (no N = 8 level)"
        if at8 is None
        else f"p99 at 8 operators {at8['p99_ms']:.1f} ms = {at8['p99_ms'] / (PERIOD * 1e3):.2f}x "
        f"the control period: target <= 1.5x {'met' if at8['p99_ms'] <= 75 else 'NOT met'}"
    )
    lines = [
        "# `elicit-jax serve` under load (bench_serve.py)",
        "",
        f"{dt.datetime.now().isoformat(timespec='seconds')} on {platform.node()} "
        f"({os.cpu_count()} CPUs), {time.time() - started:.0f} s in all; "
        f"`python benchmarks/bench_serve.py --levels {args.levels} --duration {args.duration:g}`.",
        f"Process niceness {os.nice(0)} (the servers inherit it). "
        f"Load average (1 min) at the start: {args.load_start:.1f}; {busy_text(args.busy)}"
        + (" — a quiet run will differ." if args.busy is None or args.busy > 0.5 else "."),
        "",
        "Each simulated operator: reach-pillar, informed mode (live scorer every step), an "
        "action message every 50 ms, episodes of 100 steps started back to back; intervals "
        "between consecutive frames of an episode at the client (episode boundaries left out). "
        "An episode's last frame is sent before the episode is judged and written; "
        "the p99 is also shown without those frames.",
        "",
        "## elicit-jax serve --demo",
        "",
        *_table(ours),
        "",
        f"**{verdict}.**",
        "",
        "## Reference: a bare 50 ms ticker on the same stack (Starlette, uvicorn), no physics",
        "",
        *_table(ref),
        "",
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    path.with_suffix(".json").write_text(json.dumps({"ours": ours, "reference": ref}, indent=1))


def main() -> None:
    args = _args()
    if args.reference_server is not None:
        run_reference_server(args.reference_server)
        return
    started = time.time()
    args.busy = busy_cores()
    args.load_start = os.getloadavg()[0]
    levels = [int(x) for x in args.levels.split(",")]
    cli = [sys.executable, "-c", "from elicit_jax.cli import main; main()"]
    procs = []
    try:
        with tempfile.TemporaryDirectory(prefix="bench-serve-") as tmp:
            print("starting the reference ticker ...", flush=True)
            ref_proc, ref_url = start_server([sys.executable, __file__, "--reference-server", "0"])
            procs.append(ref_proc)
            ref = asyncio.run(measure(ref_url, ref_proc.pid, levels, args.duration, "ref"))
            stop_server(ref_proc)
            print("starting elicit-jax serve --demo (builds the demo inputs once) ...", flush=True)
            proc, url = start_server(
                [
                    *cli,
                    "serve",
                    "--demo",
                    "--sessions",
                    str(Path(tmp) / "sessions"),
                    "--port",
                    "0",
                    "--practice",
                    "0",
                    "--prompt",
                    "0",
                    "--demos",
                    "1000",
                    "--max-episodes",
                    "100000",
                    "--max-operators",
                    str(max(levels)),
                ]
            )
            procs.append(proc)
            ours = asyncio.run(measure(url, proc.pid, levels, args.duration, "op"))
            stop_server(proc)
    finally:
        for p in procs:
            stop_server(p)
    write_report(args.out, ours, ref, args, started)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
