"""Demonstration data: the Parquet artifact and importers/exporters of real formats."""

from elicit_jax.data.demos import DEMOS_SCHEMA_VERSION, Demos, ObsField, read_demos, write_demos

__all__ = ["DEMOS_SCHEMA_VERSION", "Demos", "ObsField", "read_demos", "write_demos"]
