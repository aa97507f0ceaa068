"""The simulated robot: physics backends, their model files, IMU and what a client reads off them.

Below every client that runs a simulated robot (the simulator, the bridge's emulated plant, the
live view); it knows no scenario, server session or picture.
"""

__all__: list[str] = []
