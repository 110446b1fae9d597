"""Arrow <-> NumPy conversions for the demonstration artifact's columns."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.data.demo_set import Demos
from elicit_jax.errors import ElicitError


def demos_to_table(demos: Demos) -> Any:
    """A ``pyarrow.Table`` of the core columns (obs/action as fixed-size lists) and extras."""
    import pyarrow as pa

    def fixed(arr: np.ndarray, dtype: Any = np.float32) -> pa.Array:
        arr = np.ascontiguousarray(arr, dtype=dtype)
        return pa.FixedSizeListArray.from_arrays(pa.array(arr.reshape(-1)), arr.shape[1])

    cols = {
        "episode": pa.array(demos.episode.astype(np.int64)),
        "operator": pa.array(demos.operator.astype(str).tolist(), type=pa.string()),
        "step": pa.array(demos.step.astype(np.int32)),
        "obs": fixed(demos.obs),
        "action": fixed(demos.action),
        "reward": pa.array(demos.reward.astype(np.float32)),
        "success": pa.array(demos.success.astype(bool)),
    }
    for k, v in demos.extra.items():
        v = np.asarray(v)
        if k in cols:
            raise ElicitError(f"extra column '{k}' clashes with a core column")
        if v.ndim == 2 and v.dtype.kind in "biuf":
            cols[k] = fixed(v, v.dtype)
        elif v.ndim == 1:
            cols[k] = pa.array(v.tolist() if v.dtype == object else v)
        else:
            raise ElicitError(f"extra column '{k}' must be 1-D or 2-D numeric, got {v.shape}")
    return pa.table(cols)


def read_table(path: str | Path, columns: list[str] | None = None) -> Any:
    """Read a Parquet table (only ``columns`` if given); unreadable input becomes a one-line
    :class:`ElicitError`."""
    import pyarrow.parquet as pq

    try:
        return pq.read_table(path, columns=columns)
    except Exception as e:  # pyarrow raises several types for corrupt input
        raise ElicitError(f"not a readable Parquet file ({type(e).__name__}: {e})", path) from e


def parse_bound(v: Any) -> float | tuple[float, ...]:
    """A header action bound: a scalar or a per-dimension tuple."""
    return tuple(float(x) for x in v) if isinstance(v, list | tuple) else float(v)


def numeric_column(table: Any, name: str, dtype: Any, path: Any) -> np.ndarray:
    """A numeric or boolean column as ``dtype``; other types are an error."""
    import pyarrow as pa

    col = table.column(name)
    if not (
        pa.types.is_integer(col.type)
        or pa.types.is_floating(col.type)
        or pa.types.is_boolean(col.type)
    ):
        raise ElicitError(f"column '{name}' must be numeric, got {col.type}", path)
    return col.to_numpy().astype(dtype)


def column_to_numpy(table: Any, name: str, path: Any) -> np.ndarray:
    """An extra column: fixed-size lists as (N, d) of their value type, strings as objects."""
    import pyarrow as pa

    col = table.column(name)
    if pa.types.is_fixed_size_list(col.type):
        return fixed_to_numpy(table, name, path, dtype=col.type.value_type.to_pandas_dtype())
    if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
        return np.asarray(col.to_pylist(), dtype=object)
    return col.to_numpy()


def fixed_to_numpy(table: Any, name: str, path: Any, dtype: Any = np.float32) -> np.ndarray:
    """A fixed-size-list column as (N, width) ``dtype``."""
    import pyarrow as pa

    col = table.column(name).combine_chunks()
    if not pa.types.is_fixed_size_list(col.type):
        raise ElicitError(
            f"column '{name}' must be a fixed-size list of float32, got {col.type}", path
        )
    if col.null_count:
        raise ElicitError(f"column '{name}' has {col.null_count} null rows", path)
    width = col.type.list_size
    return col.flatten().to_numpy(zero_copy_only=False).astype(dtype).reshape(-1, width)
