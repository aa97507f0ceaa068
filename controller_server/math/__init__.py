"""The bottom layer of the server: small spatial algebra and damped least squares.

Nothing here knows a robot, a task or a session; every other layer may use it.
"""

__all__: list[str] = []
