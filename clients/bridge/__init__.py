"""The hardware bridge: a Poise client that drives a physical biped's actuators.

Each tick it reads every actuator, sends the robot state to the server, and
turns the joint torques it gets back into actuator commands (see
``docs/bridge.md``). Protocols (MIT-mode and Damiao CAN, ODrive CANSimple,
Dynamixel Protocol 2.0) are pure encode/decode functions in
:mod:`clients.bridge.protocols` with a thin I/O layer each; emulated
actuators that answer byte for byte like the real ones are in
:mod:`clients.bridge.emulators`.
"""

__all__: list[str] = []
