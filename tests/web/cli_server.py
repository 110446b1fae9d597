"""An `elicit-jax` server command (`serve`, `review`) in a subprocess, for the browser tests:
its output is read line by line and the URL it prints is returned."""

from __future__ import annotations

import queue
import re
import signal
import subprocess
import sys
import threading


class CliServer:
    """``elicit-jax ARGS`` in a subprocess that can be started (again) and stopped."""

    def __init__(self, *args) -> None:
        self.args = [str(a) for a in args]
        self.proc: subprocess.Popen | None = None
        self.lines: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []

    def start(self, *extra, timeout: float = 180) -> str:
        """Start the command with ``extra`` arguments; the URL it prints ("open http://…").

        Raises:
          AssertionError: no URL within ``timeout`` s, or the server died (with its output).
        """
        code = "from elicit_jax.cli import main; main()"
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code, *self.args, *map(str, extra)],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        threading.Thread(target=self._read, args=(self.proc,), daemon=True).start()
        while True:
            try:
                line = self.lines.get(timeout=timeout)
            except queue.Empty:
                raise AssertionError(
                    "the server printed no URL:\n" + "".join(self.output)
                ) from None
            url = re.search(r"open (http://\S+)", line)
            if url:
                return url.group(1)
            if self.proc.poll() is not None and self.lines.empty():
                raise AssertionError("the server died:\n" + "".join(self.output))

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            self.output.append(line)
            self.lines.put(line)

    def stop(self) -> None:
        """Interrupt the server (Ctrl-C) and wait for it; kill it after 30 s."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
