"""Shard a batched function's leading axis across devices with ``jax.sharding``.

Scoring and rollouts are batched over independent rows (state-action pairs, environments); on
a machine with several accelerators the batch axis can simply be split across them. The helper
pads the batch to a multiple of the device count, places the batched arguments with a
``NamedSharding`` over a 1-D ``("batch",)`` mesh, replicates the other arguments (e.g. a
policy's parameters), runs one jitted call and trims the padding.

Example:
    >>> act = shard_batch(lambda obs, policy: policy.act((), obs)[1], batch_argnums=(0,))
    >>> actions = act(obs, policy)        # obs: (B, obs_dim) -> actions: (B, action_dim)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError


def batch_mesh(n_devices: int | None = None) -> Any:
    """A 1-D mesh named ``batch`` over the first ``n_devices`` devices (default: all)."""
    import jax
    from jax.sharding import Mesh

    devices = jax.devices()
    n = len(devices) if n_devices is None else int(n_devices)
    if not 1 <= n <= len(devices):
        raise ElicitError(f"asked for {n} devices but JAX sees {len(devices)}")
    return Mesh(np.asarray(devices[:n]), ("batch",))


def _pad_rows(x: Any, pad: int) -> Any:
    """Repeat the last row ``pad`` times along axis 0 (a valid input, unlike zeros)."""
    import jax.numpy as jnp

    if pad == 0:
        return x
    return jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)], axis=0)


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
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec as P

    mesh = batch_mesh(n_devices)
    n = mesh.devices.size
    rows = NamedSharding(mesh, P("batch"))
    replicated = NamedSharding(mesh, P())
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
                arg = jax.tree.map(lambda x: jax.device_put(_pad_rows(x, pad), rows), arg)
            else:
                arg = jax.tree.map(lambda x: jax.device_put(x, replicated), arg)
            placed.append(arg)
        out = jitted(*placed)
        return out if pad == 0 else jax.tree.map(lambda x: x[:size], out)

    return wrapped
