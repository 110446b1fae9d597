"""Rich progress bar and end-of-run summary table for training."""

from __future__ import annotations

from types import TracebackType
from typing import Any

import numpy as np

from elicit_jax.policy.config import TrainConfig


class TrainProgress:
    """Progress of a training run: epoch, train/val loss, steps/s; a summary at the end.

    Args:
      config: the run's config.
      n_train: training samples (windows) per epoch.
      quiet: print nothing.
    """

    def __init__(self, config: TrainConfig, n_train: int, quiet: bool = False) -> None:
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.config = config
        self.n_train = n_train
        self.quiet = quiet
        from elicit_jax.runtime import stderr_width

        self.console = Console(stderr=True, quiet=quiet, width=stderr_width())
        self._bar = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[stats]}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=self.console,
            disable=quiet,
        )
        self._task: Any = None
        self._seeds: tuple[int, ...] = ()

    def __enter__(self) -> TrainProgress:
        self._bar.__enter__()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._bar.__exit__(exc_type, exc, tb)

    def start_group(self, seeds: tuple[int, ...]) -> None:
        """A new group of seeds trained together starts (compiling first)."""
        self._seeds = seeds
        label = ",".join(str(s) for s in seeds)
        self._task = self._bar.add_task(
            f"{self.config.model} seed {label}",
            total=self.config.epochs,
            stats="compiling...",
        )

    def update(self, done: int, train: np.ndarray, val: np.ndarray, seconds: float) -> None:
        """A chunk finished: ``train``/``val`` are (S, n, K) losses, ``seconds`` its wall time."""
        seconds = max(seconds, 1e-9)
        steps = -(-self.n_train // self.config.batch_size) * train.shape[1] / seconds
        rate = self.n_train * train.shape[1] * len(self._seeds) / seconds
        tl = float(np.mean(train[:, -1]))
        vl = float(np.mean(val[:, -1]))
        val_text = f"{vl:.4g}" if np.isfinite(vl) else "-"
        stats = f"train {tl:.4g}  val {val_text}  {steps:,.1f} steps/s  {rate:,.0f} samples/s"
        self._bar.update(self._task, completed=done, stats=stats)

    def warn(self, notes: list[str]) -> None:
        """Print each note as a ``warning:`` line (unless quiet)."""
        for note in notes:
            self.console.print(f"[yellow]warning:[/] {note}", soft_wrap=True)

    def summary(self, results: dict[int, tuple[np.ndarray, np.ndarray, int, float]]) -> None:
        """Print one row per seed: best epoch, best/final val loss, final train loss, time."""
        from rich.table import Table

        if self.quiet:
            return
        table = Table(title=f"{self.config.model} training ({self.config.epochs} epochs)")
        for col in ("seed", "best epoch", "best val", "final val", "final train", "time (s)"):
            table.add_column(col, justify="right")
        for seed, (train, val, best, seconds) in sorted(results.items()):

            def fmt(x: float) -> str:
                return f"{x:.4g}" if np.isfinite(x) else "-"

            best_val = float(val[best - 1].mean()) if best else float("nan")
            table.add_row(
                str(seed),
                str(best),
                fmt(best_val),
                fmt(float(val[-1].mean())),
                fmt(float(train[-1].mean())),
                f"{seconds:.1f}",
            )
        self.console.print(table)
