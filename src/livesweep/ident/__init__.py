"""Parametric identification: cost, transfer functions, state space, accuracy, verification (pure)."""
