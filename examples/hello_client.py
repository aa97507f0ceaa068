"""Connect to a running `poise serve`, send a few states, print the torques.

Usage:
    poise serve --bind tcp://127.0.0.1:5555 &
    python examples/hello_client.py tcp://127.0.0.1:5555
"""

import sys

import numpy as np

from clients import ControllerClient, neutral_joint_position
from protocol import State


def main(endpoint: str) -> None:
    """Handshake, five ticks of the standing pose, print torques and ground force."""
    # 30 s: the first hello may reach a server that was just started (`poise serve &`),
    # whose workers are still loading; a loaded machine can take more than 5 s for that.
    with ControllerClient(endpoint, timeout_s=30.0) as client:
        welcome = client.connect("thesis_humanoid", params={"stiffness": 100.0})
        print(f"{welcome.model_name}: {len(welcome.joints)} joints, {welcome.total_mass:.1f} kg")
        nv = sum(joint.nv for joint in welcome.joints)
        for tick in range(5):
            state = State(
                time_s=tick * 0.001,
                joint_position=neutral_joint_position(welcome.joints),
                joint_velocity=np.zeros(nv),
                position_base_in_world=welcome.standing_position_base_in_world,
                orientation_base_in_world_xyzw=[0.0, 0.0, 0.0, 1.0],
                linear_velocity_base_in_world=[0.0, 0.0, 0.0],
                angular_velocity_base_in_base=[0.0, 0.0, 0.0],
                contact_flags=[True] * len(welcome.contacts),
            )
            command = client.step(state)
            vertical_force_N = command.contact_force_in_world.reshape(-1, 3)[:, 2].sum()
            print(
                f"tick {tick}: max |torque| {np.abs(command.joint_torque).max():7.2f} N·m, "
                f"ground force {vertical_force_N:7.1f} N"
            )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tcp://127.0.0.1:5555")
