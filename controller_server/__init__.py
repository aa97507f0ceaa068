"""Poise controller server: robot models, controllers and the ZeroMQ server (submodules)."""

__all__: list[str] = []
