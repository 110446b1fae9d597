"""elicit-jax: measure and elicit demonstrations compatible with a base policy."""

__version__ = "0.1.0"
