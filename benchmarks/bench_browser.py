"""The operator page on a CPU: rendered frames/s and key-to-pose latency in headless Chromium.

Starts `elicit-jax serve --demo` (reach-pillar, informed mode: the live scorer runs every
step; no practice, no prompt) in a subprocess, opens the page for N operators (default 2) in
headless Chromium with software WebGL (SwiftShader: no GPU, as on a laptop without one), and
has each operator demonstrate at the same time by keyboard: every cycle presses A or D (in
turn) for 400 ms, then lets go for 500–550 ms so the gripper comes to rest (the random part
puts each press at a random phase of the server's 50 ms control step, as a person's presses
are; a fixed 900 ms cycle, 18 steps, would press at the same phase every time).

Measured in each page (the page's own clock):

* **rendered frames/s**: WebGL frames the page drew (each call of the view's ``render``),
  over the whole window and over the time a key is held (the gripper moving: what the
  operator watches; a page that draws only on change draws nothing while all rests);
* **browser CPU per drawn frame**: CPU seconds of every Chromium process (renderers and the
  GPU process, where software WebGL draws) over the window, per frame drawn by all pages —
  the drawing cost, which unlike frames/s does not depend on what else the machine runs;
* **key-to-pose latency**: from the key's ``keydown`` to the first drawn frame in which the
  gripper has moved 0.5 mm the key's way (the server applies the command at its next 50 ms
  step and streams the pose back; the page draws it); a press not drawn moving within
  900 ms is a miss;
* **key-to-frame latency**: from the ``keydown`` to the arrival of the first streamed pose
  in which the gripper has moved 0.5 mm the key's way (the server's share: the wait for its
  next step, the step, the send), so the drawing's share is the difference.

Targets (issue 33): >= 15 frames/s while moving, p95 key-to-pose <= 120 ms, with 2 operators.
``--code DIR`` serves another checkout's ``elicit_jax`` (e.g. the code before a change) with
the same measurement. Bounded: about --duration seconds plus start-up (the demo inputs are
built once into --demo-dir if missing); loopback only; every process it starts is stopped.

Run: ``python benchmarks/bench_browser.py [--code DIR] [--label NAME] [--out FILE.md]``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import queue
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from machine import busy_cores, busy_text

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "web"))
from chromium import FLAGS  # the browser tests' headless flags: the same browser

# In the page: count drawn frames, press keys, time each key to the first drawn move.
PROBE = """(duration) => new Promise((resolve) => {
  const view = window.elicit.view;
  const g = view.names.indexOf('gripper');
  const drawn = () => view.instances[0].bodies[g].position;
  const render = view.render.bind(view);
  const pose = view.pose.bind(view);
  const frames = [];
  let wait = null;
  const lat = [];
  const arrive = [];  // key to the first streamed pose that has moved (before drawing)
  let shownY = null;
  view.pose = (poses, i = 0, glide = 0) => {
    if (i === 0) {
      const y = poses[g * 7 + 1];
      if (wait && wait.arrived === null && (y - wait.a0) * wait.sign > 0.0005) {
        wait.arrived = performance.now() - wait.t0;
        arrive.push(wait.arrived);
      }
      shownY = y;
    }
    return pose(poses, i, glide);
  };
  let held = 0;
  const cost = [];
  view.render = () => {
    const r0 = performance.now();
    render();
    const now = performance.now();
    cost.push(now - r0);
    frames.push(now);
    if (wait && (drawn().y - wait.y0) * wait.sign > 0.0005) {
      lat.push(now - wait.t0);
      wait = null;
    }
  };
  const key = (code, down) => document.dispatchEvent(new KeyboardEvent(down ? 'keydown' : 'keyup',
    { code, key: code.slice(3).toLowerCase(), bubbles: true }));
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  (async () => {
    key('KeyW', true); await sleep(300); key('KeyW', false); await sleep(600);  // starts it
    const t0 = performance.now();
    let sign = 1;
    const heldSpans = [];
    while (performance.now() - t0 < duration * 1000) {
      const code = sign > 0 ? 'KeyA' : 'KeyD';
      wait = { t0: performance.now(), y0: drawn().y, a0: shownY ?? drawn().y, sign, arrived: null };
      const h0 = performance.now();
      key(code, true);
      await sleep(400);
      key(code, false);
      heldSpans.push([h0, performance.now()]);
      await sleep(500 + Math.random() * 50);  // a random phase of the server's 50 ms step
      if (wait) {  // not drawn moving within 900 ms: a miss
        lat.push(Infinity);
        if (wait.arrived === null) arrive.push(Infinity);
        wait = null;
      }
      sign = -sign;
    }
    const t1 = performance.now();
    view.render = render;
    view.pose = pose;
    const inSpans = frames.filter((t) => heldSpans.some(([a, b]) => t >= a && t <= b)).length;
    held = heldSpans.reduce((s, [a, b]) => s + (b - a), 0);
    resolve({ frames: frames.filter((t) => t >= t0 && t <= t1).length, seconds: (t1 - t0) / 1000,
              heldFrames: inSpans, heldSeconds: held / 1000,
              latencies: lat.map((x) => (Number.isFinite(x) ? x : -1)),
              arrivals: arrive.map((x) => (Number.isFinite(x) ? x : -1)),
              renderMs: cost.sort((a, b) => a - b)[Math.floor(cost.length / 2)] || 0,
              state: document.body.dataset.state });
  })();
})"""


def _args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--code", type=Path, default=Path(__file__).resolve().parents[1])
    p.add_argument("--label", default="this checkout")
    p.add_argument("--operators", type=int, default=2)
    p.add_argument("--duration", type=float, default=20.0, help="seconds measured")
    p.add_argument("--demo-dir", type=Path, default=None, help="serve --demo's cache root")
    p.add_argument("--chromium", default=os.environ.get("ELICIT_JAX_CHROMIUM") or "chromium")
    p.add_argument("--width", type=int, default=1200)
    p.add_argument("--height", type=int, default=720)
    p.add_argument("--out", type=Path, default=None, help="append a Markdown section here")
    return p.parse_args()


def start_server(code: Path, demo_dir: Path | None, sessions: Path) -> tuple:
    args = ["serve", "--demo", "--sessions", str(sessions), "--port", "0", "--practice", "0"]
    args += ["--prompt", "0", "--demos", "1", "--max-episodes", "3", "--horizon", "2000"]
    if demo_dir is not None:
        args += ["--demo-dir", str(demo_dir)]
    env = {**os.environ, "PYTHONPATH": str(code)}
    proc = subprocess.Popen(
        [sys.executable, "-c", "from elicit_jax.cli import main; main()", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(x) for x in proc.stdout], daemon=True).start()
    out = []
    while True:
        try:
            line = lines.get(timeout=600)
        except queue.Empty:
            proc.kill()
            raise SystemExit("the server printed no URL:\n" + "".join(out)) from None
        out.append(line)
        m = re.search(r"open (http://\S+)", line)
        if m:
            return proc, m.group(1)
        if proc.poll() is not None and lines.empty():
            raise SystemExit("the server died:\n" + "".join(out))


def tree_cpu(root: int) -> float:
    """CPU seconds (user + system) of ``root``'s descendants (not ``root`` itself): here the
    Playwright driver and every Chromium process (browser, renderers, GPU)."""
    parent, cpu = {}, {}
    tick = os.sysconf("SC_CLK_TCK")
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            f = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(d.name)] = int(f[1])
        cpu[int(d.name)] = (int(f[11]) + int(f[12])) / tick
    total = 0.0
    for pid in cpu:
        q = parent.get(pid)
        while q and q != root:
            q = parent.get(q)
        if q == root and pid != root:
            total += cpu[pid]
    return total


def pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, round(q / 100 * (len(s) - 1))))] if s else float("nan")


def measure(a: argparse.Namespace) -> dict:
    from playwright.sync_api import sync_playwright

    chromium = shutil.which(a.chromium) or a.chromium
    with tempfile.TemporaryDirectory(prefix="bench-browser-") as tmp:
        proc, url = start_server(a.code.resolve(), a.demo_dir, Path(tmp) / "sessions")
        try:
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=chromium, args=FLAGS)
                pages = []
                for i in range(a.operators):
                    ctx = browser.new_context(viewport={"width": a.width, "height": a.height})
                    page = ctx.new_page()
                    page.goto(url)
                    page.wait_for_selector("#name")
                    page.fill("#name", f"op{i}")
                    page.keyboard.press("Enter")
                    page.wait_for_selector(
                        "body[data-screen=demonstrate][data-state=ready]",
                        state="attached",
                        timeout=120_000,
                    )
                    page.wait_for_function("() => elicit.view.instances.length > 0")
                    pages.append(page)
                renderer = pages[0].evaluate(
                    """() => { const gl = document.createElement('canvas').getContext('webgl2');
                    const e = gl.getExtension('WEBGL_debug_renderer_info');
                    return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : '?'; }"""
                )
                busy0 = os.getloadavg()[0]
                cpu0, wall0 = tree_cpu(os.getpid()), time.monotonic()
                for page in pages:  # all operators demonstrate at once
                    page.evaluate(
                        f"(d) => {{ window.__bench = null; ({PROBE})(d).then((r) => "
                        "{ window.__bench = r; }); }",
                        a.duration,
                    )
                results = []
                for page in pages:
                    page.wait_for_function(
                        "() => window.__bench !== null", timeout=(a.duration + 60) * 1000
                    )
                    results.append(page.evaluate("window.__bench"))
                cpu1, wall1 = tree_cpu(os.getpid()), time.monotonic()
                busy1 = busy_cores()
                load1 = os.getloadavg()[0]
                browser.close()
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
    return {
        "renderer": renderer,
        "pages": results,
        "load_before": busy0,
        "busy_after": busy1,
        "load_after": load1,
        "browser_cpu_s": cpu1 - cpu0,
        "browser_wall_s": wall1 - wall0,
    }


def summarise(r: dict) -> dict:
    lat = [x for p in r["pages"] for x in p["latencies"]]
    ok = [x for x in lat if x >= 0]
    per_page = [
        (p["frames"] / p["seconds"], p["heldFrames"] / max(p["heldSeconds"], 1e-9))
        for p in r["pages"]
    ]
    arr = [x for p in r["pages"] for x in p.get("arrivals", [])]
    arr_ok = [x for x in arr if x >= 0]
    return {
        "frame_p50": pct(arr_ok, 50),
        "frame_p95": pct(arr_ok, 95) if len(arr_ok) == len(arr) else float("inf"),
        "fps_all": min(x for x, _ in per_page),
        "fps_moving": min(y for _, y in per_page),
        "lat_p50": pct(ok, 50),
        "lat_p95": pct(ok, 95) if len(ok) == len(lat) else float("inf"),
        "lat_max": max(ok) if ok else float("nan"),
        "presses": len(lat),
        "missed": len(lat) - len(ok),
        "render_ms": max(p["renderMs"] for p in r["pages"]),
        "cpu_per_frame_ms": 1e3 * r["browser_cpu_s"] / max(sum(p["frames"] for p in r["pages"]), 1),
        "browser_cores": r["browser_cpu_s"] / r["browser_wall_s"],
    }


def main() -> None:
    a = _args()
    t0 = time.time()
    r = measure(a)
    s = summarise(r)
    command = "python benchmarks/bench_browser.py " + " ".join(
        x if " " not in x else f"'{x}'" for x in sys.argv[1:]
    )
    fps_ok, lat_ok = s["fps_moving"] >= 15, s["lat_p95"] <= 120
    lines = [
        f"## {a.label}",
        "",
        f"{dt.datetime.now().isoformat(timespec='seconds')} on {platform.node()} "
        f"({os.cpu_count()} CPUs), {time.time() - t0:.0f} s; `{command.strip()}`. "
        f"Renderer: {r['renderer']}. {a.operators} operators at once, {a.width}x{a.height} "
        f"each. Load average (1 min) before: {r['load_before']:.1f}; "
        f"{busy_text(r['busy_after'])}.",
        "",
        "| frames/s while moving (worst page) | frames/s overall (worst page) | key-to-pose "
        "p50 | p95 | max | key-to-frame p50 | p95 | key presses (missed) | browser CPU per "
        "drawn frame | browser CPU (cores) | load average (1 min) before, after |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        f"| {s['fps_moving']:.1f} | {s['fps_all']:.1f} | {s['lat_p50']:.0f} ms | "
        f"{s['lat_p95']:.0f} ms | {s['lat_max']:.0f} ms | {s['frame_p50']:.0f} ms | "
        f"{s['frame_p95']:.0f} ms | {s['presses']} ({s['missed']}) | "
        f"{s['cpu_per_frame_ms']:.1f} ms | {s['browser_cores']:.2f} | "
        f"{r['load_before']:.1f}, {r['load_after']:.1f} |",
        "",
        f"Targets: >= 15 frames/s while moving ({'met' if fps_ok else 'MISSED'}), p95 "
        f"key-to-pose <= 120 ms ({'met' if lat_ok else 'MISSED'}).",
        "",
        "<details><summary>per page</summary>\n\n```json\n"
        + json.dumps(r["pages"], indent=1)
        + "\n```\n</details>",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        with a.out.open("a") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
