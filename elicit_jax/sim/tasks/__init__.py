"""Task definitions, one task class per module; :data:`elicit_jax.sim.registry.TASKS` names
each task's class (its ``factory``)."""
