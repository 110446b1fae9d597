"""Task definitions; each module registers its task class with :func:`register_task`."""
