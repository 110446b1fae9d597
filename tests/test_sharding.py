"""Batch-axis sharding across forced host devices (run in a subprocess: the device count is
fixed when JAX starts)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp, numpy as np
    from elicit_jax.sharding import shard_batch

    assert len(jax.devices()) == 2, jax.devices()

    def f(x, w):
        return {"y": jnp.tanh(x @ w["a"]) + w["b"], "n": jnp.sum(x * x, axis=1)}

    rng = np.random.default_rng(0)
    w = {"a": jnp.asarray(rng.normal(size=(3, 4)), jnp.float32), "b": jnp.float32(0.5)}
    sharded = shard_batch(f, 2, batch_argnums=(0,))
    for b in (6, 5, 1):   # divisible, padded, a single row
        x = jnp.asarray(rng.normal(size=(b, 3)), jnp.float32)
        out, ref = sharded(x, w), jax.jit(f)(x, w)
        assert out["y"].shape == (b, 4) and out["n"].shape == (b,)
        np.testing.assert_allclose(out["y"], ref["y"], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(out["n"], ref["n"], rtol=1e-6, atol=1e-6)
        if b == 6:
            assert len(out["y"].sharding.device_set) == 2
            shards = {s.device: s.data.shape for s in out["y"].addressable_shards}
            assert sorted(shards.values()) == [(3, 4), (3, 4)], shards
    try:
        shard_batch(f, 3)
    except Exception as e:
        assert "asked for 3 devices but JAX sees 2" in str(e)
    else:
        raise AssertionError("3 devices accepted")
    print("OK")
    """
)


def test_shard_batch_splits_rows_across_two_forced_host_devices():
    env = dict(os.environ)
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    ).strip()
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip().endswith("OK")
