"""Poise controller server: robot models, controllers and the ZeroMQ server."""
