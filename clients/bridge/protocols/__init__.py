"""Actuator protocols: pure encode/decode functions, and a thin I/O layer each (an ActuatorBus)."""

__all__: list[str] = []
