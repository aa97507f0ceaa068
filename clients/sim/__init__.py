"""Simulator client: physics backends, scenarios, metrics (import the submodules)."""

__all__: list[str] = []
