"""Base policies: MLP / MDN / LSTM ensembles, their training loop and checkpoints.

Heavy modules (JAX, Flax) are imported by the submodules, not here.
"""
