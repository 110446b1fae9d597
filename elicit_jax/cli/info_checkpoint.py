"""``elicit-jax info`` for training runs and checkpoints."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from elicit_jax.policy.checkpoint import (
    CHECKPOINT_KIND,
    checkpoint_problems,
    checkpoint_spec,
    list_checkpoints,
    seed_dirs,
)
from elicit_jax.policy.kinds import MODEL_KINDS


def _fmt(x: Any) -> str:
    return "-" if x is None else f"{x:.4g}" if isinstance(x, float) else str(x)


def _model_line(header: dict[str, Any]) -> str:
    m = header["model"]
    sizes = "x".join(str(h) for h in m["hidden"])
    kind = MODEL_KINDS.get(m["kind"])
    extra = kind.describe(m) if kind is not None else ""
    return (
        f"{m['kind']} x{m['n_members']} members, hidden {sizes}, dropout {m['dropout']}{extra}; "
        f"obs_dim {m['obs_dim']}, action_dim {m['action_dim']}"
    )


def _epochs_text(epochs: list[int]) -> str:
    if len(epochs) <= 3:
        return ", ".join(str(e) for e in epochs)
    return f"{epochs[0]}, {epochs[1]}, ..., {epochs[-1]}"


def describe_run(path: Path, header: dict[str, Any]) -> None:
    """Print config, dims, seeds and per-seed best epoch / losses of a run or checkpoint."""
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.artifact import read_header

    checkpoint_spec(header, Path(path))  # no model kind: one line, before printing anything
    console = Console()
    console.print(f"[bold]{path}[/]: {header['kind']} (schema v{header['schema_version']})")
    console.print(f"  model: {_model_line(header)}")
    fields = header["model"].get("obs_fields") or []
    if fields:
        console.print(f"  obs fields: {', '.join(fields)}")
    cfg = header.get("config", {})
    keys = (
        "epochs",
        "lr",
        "batch_size",
        "checkpoint_every",
        "val_fraction",
        "bootstrap",
        "grad_clip",
        "seq_len",
    )
    console.print("  config: " + ", ".join(f"{k}={cfg.get(k)}" for k in keys if k in cfg))
    for name, inp in header.get("inputs", {}).items():
        console.print(f"  input {name}: {inp['path']} (sha256 {inp['sha256'][:12]})")
    console.print(f"  data sha256: {header.get('data_sha256', '?')[:12]}")
    if header["kind"] == CHECKPOINT_KIND:
        console.print(
            f"  episodes: {len(header['train_episodes'])} train, "
            f"{len(header['val_episodes'])} val; trained in {header['train_seconds']} s"
        )
    table = Table()
    for col in ("seed", "best epoch", "best val", "final val", "final train", "saved epochs"):
        table.add_column(col, justify="right")
    ckpts = list_checkpoints(path)
    for seed, d in sorted(seed_dirs(path).items()):
        h = read_header(d)
        table.add_row(
            str(seed),
            _fmt(h.get("best_epoch")),
            _fmt(h.get("best_val_loss")),
            _fmt(h.get("final_val_loss")),
            _fmt(h.get("final_train_loss")),
            _epochs_text([c for c in ckpts[seed] if isinstance(c, int)]),
        )
    console.print(table)
    console.print(f"  versions: {header.get('versions', {})}")
    for note in header.get("warnings", []):
        console.print(f"  [yellow]warning:[/] {note}", soft_wrap=True)
    problems = checkpoint_problems(path)
    n_bad = sum(bool(p) for p in problems.values())
    if not n_bad:
        console.print(
            "  [green]check: ok[/] (every parameter file opens, is finite, fits the model and "
            "is the file training wrote)"
        )
        return
    console.print(f"  [bold red]check: {n_bad} of {len(problems)} seeds have problems[/]")
    for seed, found in problems.items():
        for p in found:
            console.print(f"    [red]seed {seed}:[/] {p}", soft_wrap=True)
