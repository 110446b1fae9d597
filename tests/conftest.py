"""Test configuration: XLA flags and the compilation cache must be set before JAX loads.

The tests step MJX, so XLA's CPU pool gets the threads MJX needs (``mjx=True``).
"""

from elicit_jax.runtime import configure

configure(mjx=True)
