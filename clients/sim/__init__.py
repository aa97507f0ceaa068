"""Simulator client: physics backends, scenarios, metrics."""
