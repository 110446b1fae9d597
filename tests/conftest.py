"""Test configuration: XLA flags and the compilation cache must be set before JAX loads."""

from elicit_jax.runtime import configure

configure()
