"""Shard a batched function's leading axis across devices with ``jax.sharding``.

Scoring and rollouts are batched over independent rows (state-action pairs, environments); on
a machine with several accelerators the batch axis can simply be split across them. The
batch is padded to a multiple of the device count (by repeating its last row, a valid input),
the batched arguments are placed with a ``NamedSharding`` over a 1-D ``("batch",)`` mesh, the
other arguments (e.g. a policy's parameters) are replicated, one jitted call runs on every
device and the padding is trimmed. With one device nothing is placed or copied.

Example:
    >>> act = shard_batch(lambda obs, policy: policy.act((), obs)[1], batch_argnums=(0,))
    >>> actions = act(obs, policy)        # obs: (B, obs_dim) -> actions: (B, action_dim)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError


def device_count(n_devices: int | None = None) -> int:
    """The number of devices to shard over: ``n_devices`` checked, or all that JAX sees."""
    import jax

    available = jax.device_count()
    n = available if n_devices is None else int(n_devices)
    if not 1 <= n <= available:
        raise ElicitError(f"asked for {n} devices but JAX sees {available}")
    return n


def devices_for(batch: int, n_devices: int | None = None) -> int:
    """Devices worth using for a batch of ``batch`` rows: at most one per row."""
    return max(1, min(device_count(n_devices), int(batch)))


def round_up(n: int, multiple: int) -> int:
    """The smallest multiple of ``multiple`` that is at least ``n``."""
    return -(-int(n) // int(multiple)) * int(multiple)


def batch_mesh(n_devices: int | None = None) -> Any:
    """A 1-D mesh named ``batch`` over the first ``n_devices`` devices (default: all)."""
    import jax
    from jax.sharding import Mesh

    n = device_count(n_devices)
    return Mesh(np.asarray(jax.devices()[:n]), ("batch",))


def batch_shardings(n_devices: int | None = None) -> tuple[Any, Any]:
    """``(rows, replicated)``: shardings that split axis 0 across the mesh / copy to all."""
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec as P

    mesh = batch_mesh(n_devices)
    return NamedSharding(mesh, P("batch")), NamedSharding(mesh, P())


def pad_rows(x: Any, pad: int) -> Any:
    """Repeat the last row ``pad`` times along axis 0 (numpy stays numpy)."""
    if pad == 0:
        return x
    if isinstance(x, np.ndarray):
        return np.concatenate([x, np.repeat(x[-1:], pad, axis=0)], axis=0)
    import jax.numpy as jnp

    return jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)], axis=0)


def place(tree: Any, sharding: Any) -> Any:
    """Put every array of ``tree`` on devices with ``sharding``."""
    import jax

    return jax.tree.map(lambda x: jax.device_put(x, sharding), tree)


def shard_batch(
    fn: Callable[..., Any],
    n_devices: int | None = None,
    *,
    batch_argnums: Sequence[int] = (0,),
) -> Callable[..., Any]:
    """Wrap ``fn`` so the leading axis of its batched arguments is split across devices.

    Args:
      fn: a function whose batched arguments (pytrees of arrays ``(B, ...)``) and whose
        outputs (pytrees of arrays ``(B, ...)``) share the leading batch axis; rows must be
        independent.
      n_devices: devices to use (default: all that JAX sees).
      batch_argnums: positions of the batched arguments; the others are replicated.

    Returns:
      ``wrapped(*args)`` with ``fn``'s outputs; ``B`` need not divide the device count.
    """
    import jax

    n = device_count(n_devices)
    rows, replicated = batch_shardings(n)
    jitted = jax.jit(fn)
    batch_argnums = tuple(batch_argnums)

    def wrapped(*args: Any) -> Any:
        leaves = [leaf for i in batch_argnums for leaf in jax.tree.leaves(args[i])]
        if not leaves:
            raise ElicitError("shard_batch: no batched array among the batched arguments")
        size = int(leaves[0].shape[0])
        if any(int(leaf.shape[0]) != size for leaf in leaves):
            raise ElicitError("shard_batch: batched arguments disagree on the batch size")
        pad = (-size) % n
        placed = []
        for i, arg in enumerate(args):
            if i in batch_argnums:
                arg = place(jax.tree.map(lambda x: pad_rows(x, pad), arg), rows)
            else:
                arg = place(arg, replicated)
            placed.append(arg)
        out = jitted(*placed)
        return out if pad == 0 else jax.tree.map(lambda x: x[:size], out)

    return wrapped


def row_placer(devices: int) -> Callable[..., Any] | None:
    """``place(x, replicate=False)`` putting arrays on a 1-D mesh of ``devices`` devices
    (rows split, or replicated), or ``None`` for one device (nothing is moved or copied)."""
    if devices == 1:
        return None
    rows, replicated = batch_shardings(devices)
    return lambda x, replicate=False: place(x, replicated if replicate else rows)
