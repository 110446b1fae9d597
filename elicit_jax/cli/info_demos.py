"""``elicit-jax info`` for data artifacts (demos, episode lists) and raw source datasets."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError
from elicit_jax.stats import sample_std


def _console() -> Any:
    from rich.console import Console

    return Console()


def kv_table(title: str, rows: list[tuple[str, Any]]) -> Any:
    """A two-column table of (name, value) rows (``None`` shown as ``-``)."""
    from rich.table import Table

    table = Table(title=title, show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column(overflow="fold")
    for k, v in rows:
        table.add_row(k, "-" if v is None else str(v))
    return table


def _bound_text(v: Any) -> str:
    if isinstance(v, list | tuple):
        return "[" + ", ".join(f"{float(x):.3g}" for x in v) + "]"
    return "?" if v is None else f"{float(v):.3g}"


def _id_names(path: str | Path, show: int = 3) -> str:
    """``0 (demo_0), 1 (demo_1), …, 49 (demo_49)``: ids with their names in the source."""
    import pyarrow.parquet as pq

    have = pq.read_schema(path).names
    cols = ["episode", "source_episode"] if "source_episode" in have else ["episode"]
    table = pq.read_table(path, columns=cols)
    ids, first = np.unique(table.column("episode").to_numpy(), return_index=True)
    names = (
        np.asarray(table.column("source_episode").to_pylist(), dtype=object)[first]
        if len(cols) == 2
        else None
    )
    text = [f"{i}" + (f" ({names[k]})" if names is not None else "") for k, i in enumerate(ids)]
    if len(text) > 2 * show:
        text = [*text[:show], "…", *text[-show:]]
    return ", ".join(text)


def success_recorded(header: dict[str, Any]) -> bool:
    """False when the importer assumed every episode successful (no success or reward data):
    a success rate is then unknown, not 100%."""
    source = str(header.get("provenance", {}).get("success_from", ""))
    return not source.startswith("assumed")


def success_text(rate: float, recorded: bool) -> str:
    """A success rate for tables, or ``unknown`` when the data never recorded it."""
    return f"{100 * rate:.1f}%" if recorded else "unknown"


def operator_stats(path: str | Path) -> list[dict[str, Any]]:
    """Per-operator episode counts, mean/std episode length and success rate (plus 'all').

    Reads only the ``episode``, ``operator`` and ``success`` columns.
    """
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path, columns=["episode", "operator", "success"])
    except Exception as e:  # pyarrow raises several types for missing columns/corrupt files
        raise ElicitError(f"cannot read demo columns ({type(e).__name__}: {e})", path) from e
    ep = table.column("episode").to_numpy()
    op = np.asarray(table.column("operator").to_pylist(), dtype=object)
    ok = table.column("success").to_numpy(zero_copy_only=False).astype(bool)
    ids, first, lengths = np.unique(ep, return_index=True, return_counts=True)
    ep_op, ep_ok = op[first], ok[first]
    rows = []
    for name in [*sorted(set(ep_op.tolist())), None]:
        sel = np.ones(len(ids), bool) if name is None else ep_op == name
        n = lengths[sel]
        rows.append(
            {
                "operator": "all" if name is None else name,
                "episodes": int(sel.sum()),
                "steps": int(n.sum()),
                "mean_length": float(n.mean()),
                "std_length": sample_std(n),
                "success_rate": float(ep_ok[sel].mean()),
            }
        )
    return rows


def operator_table(path: Path, header: dict[str, Any], title: str, spread: bool) -> Any:
    """The table of episodes per operator (and 'all'): counts, steps, length, success.

    Args:
      path: the demos artifact.
      header: its header (whether it recorded success).
      title: the table's title.
      spread: also the length's std, and the 'all' row in bold (``info``; ``import`` shows
        the plain table of what it wrote).
    """
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    cols = ("operator", "episodes", "steps", "length mean", "length std", "success")
    for col in cols if spread else tuple(c for c in cols if c != "length std"):
        table.add_column(col, justify="left" if col == "operator" else "right")
    recorded = success_recorded(header)
    for r in operator_stats(path):
        std = [f"{r['std_length']:.1f}"] if spread else []
        cells = [r["operator"], str(r["episodes"]), str(r["steps"]), f"{r['mean_length']:.1f}"]
        bold = spread and r["operator"] == "all"
        table.add_row(
            *cells, *std, success_text(r["success_rate"], recorded), style="bold" if bold else None
        )
    return table


def describe_demos(path: Path, header: dict[str, Any]) -> None:
    """Overview, observation fields, per-operator statistics and provenance of a demos file."""
    from rich.table import Table

    console = _console()
    console.print(f"[bold]{path}[/]: demonstrations (schema v{header.get('schema_version')})")
    low, high = _bound_text(header.get("action_low")), _bound_text(header.get("action_high"))
    console.print(
        kv_table(
            "overview",
            [
                ("task", header.get("task")),
                ("episodes", header.get("n_episodes")),
                ("steps", header.get("n_steps")),
                ("obs dim", header.get("obs_dim")),
                ("action dim", header.get("action_dim")),
                (
                    "action bounds",
                    f"{low} .. {high} ({header.get('action_bounds_policy', 'error')})",
                ),
                ("episode ids (source name)", _id_names(path)),
                ("extra columns", ", ".join(header.get("extra_columns", [])) or None),
                ("created", header.get("created")),
                ("elicit-jax", header.get("versions", {}).get("elicit-jax")),
            ],
        )
    )
    fields = Table(title="observation fields", title_justify="left")
    for col in ("field", "slice", "size"):
        fields.add_column(col)
    for name, (a, b) in header.get("obs_fields", {}).items():
        fields.add_row(name, f"{a}:{b}", str(b - a))
    console.print(fields)
    console.print(operator_table(path, header, "episodes per operator", spread=True))
    prov = dict(header.get("provenance", {}))
    console.print(kv_table("provenance", sorted(prov.items())))


def describe_episode_list(path: Path, header: dict[str, Any]) -> None:
    """Size, source and operators of an episode-list selection."""
    console = _console()
    console.print(f"[bold]{path}[/]: episode list (schema v{header.get('schema_version')})")
    ops = header.get("operators", [])
    counts = {o: ops.count(o) for o in sorted(set(ops))}
    names = header.get("source_episodes", [])
    shown = ", ".join(map(str, names[:12])) + (" ..." if len(names) > 12 else "")
    source = header.get("source", {})
    console.print(
        kv_table(
            "selection",
            [
                ("episodes", header.get("n_episodes")),
                ("source episodes", shown),
                ("per operator", ", ".join(f"{k}: {v}" for k, v in counts.items())),
                ("source", source.get("source")),
                ("source sha256", source.get("sha256")),
                ("importer", source.get("importer")),
                ("created", header.get("created")),
            ],
        )
    )


def describe_robomimic_file(path: Path) -> None:
    """Summary of a raw robomimic HDF5 file: task, demos, obs keys and masks."""
    from rich.table import Table

    from elicit_jax.data.robomimic import demo_names, open_hdf5, read_mask, task_name

    console = _console()
    with open_hdf5(path) as f:
        names = demo_names(f, path)
        first = f["data"][names[0]]
        lengths = [int(f["data"][n]["actions"].shape[0]) for n in names]
        console.print(f"[bold]{path}[/]: robomimic dataset (not yet imported)")
        console.print(
            kv_table(
                "overview",
                [
                    ("task", task_name(f, path)),
                    ("demos", len(names)),
                    ("steps", sum(lengths)),
                    ("length mean/std", f"{np.mean(lengths):.1f} / {sample_std(lengths):.1f}"),
                    ("action shape", first["actions"].shape[1:]),
                ],
            )
        )
        keys = Table(title=f"obs keys (of {names[0]})", title_justify="left")
        keys.add_column("key")
        keys.add_column("shape per step")
        for k in sorted(first["obs"].keys()) if "obs" in first else []:
            keys.add_row(k, str(first["obs"][k].shape[1:]))
        console.print(keys)
        masks = Table(title="masks (filter keys)", title_justify="left")
        masks.add_column("key")
        masks.add_column("demos", justify="right")
        for k in sorted(f["mask"].keys()) if "mask" in f else []:
            masks.add_row(k, str(len(read_mask(f, k, path))))
        console.print(masks)


def describe_lerobot_folder(path: Path) -> None:
    """Summary of a raw LeRobot dataset folder: version, episodes, tasks and features."""
    from rich.table import Table

    from elicit_jax.data.lerobot import read_episodes, read_info, read_tasks

    info = read_info(path)
    rows = read_episodes(path, info)
    lengths = [int(r["length"]) for r in rows] or [0]
    console = _console()
    console.print(f"[bold]{path}[/]: LeRobot dataset {info['codebase_version']} (not yet imported)")
    console.print(
        kv_table(
            "overview",
            [
                ("robot", info.get("robot_type")),
                ("fps", info.get("fps")),
                ("episodes", len(rows)),
                ("frames", sum(lengths)),
                ("length mean/std", f"{np.mean(lengths):.1f} / {sample_std(lengths):.1f}"),
                ("tasks", " | ".join(read_tasks(path, info).values())),
            ],
        )
    )
    feats = Table(title="features", title_justify="left")
    for col in ("feature", "dtype", "shape"):
        feats.add_column(col)
    for name, ft in info["features"].items():
        feats.add_row(name, str(ft.get("dtype")), str(ft.get("shape")))
    console.print(feats)


def describe_export(path: Path, header: dict[str, Any]) -> None:
    """A LeRobot folder written by ``export``: the dataset, then what it came from."""
    if path.is_dir() and (path / "meta" / "info.json").is_file():
        describe_lerobot_folder(path)
    selection = header.get("inputs", {}).get("selection", {})
    ops = [str(e.get("operator")) for e in header.get("episodes", [])]
    counts = {o: ops.count(o) for o in sorted(set(ops))}
    rows = [
        (
            "written from",
            f"{selection.get('path')} (sha256 {str(selection.get('sha256'))[:12]}...)",
        ),
        ("created", header.get("created")),
        ("per operator", ", ".join(f"{k}: {v}" for k, v in counts.items()) or None),
    ]
    rows += [("note", n) for n in header.get("notes", [])]
    _console().print(kv_table("export", rows))
