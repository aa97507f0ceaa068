"""Emulated actuators that answer byte for byte like the real ones.

Each emulator pairs a protocol's frames with :class:`EmulatedMotor`, the
physics every actuator shares (its firmware's torque law, torque limit,
a first-order thermal model and injectable faults). A plant
(:class:`clients.bridge.plant.Plant`) puts each motor on a joint of a
simulated robot, so a whole robot runs through the bridge without hardware.
"""

__all__: list[str] = []
