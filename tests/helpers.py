"""Helpers shared by tests: random wire states, an independent dynamics check, the CLI."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import av
import numpy as np
import pinocchio as pin
from hypothesis import settings
from scipy.spatial.transform import Rotation

from clients.sampling import random_state  # noqa: F401  (re-exported for tests)
from protocol.messages import Command, State, Welcome


def free_port() -> int:
    """A TCP port free on loopback now (for a server a test starts, or one that is not there)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def examples(nightly: int) -> int:
    """How many examples a large property or fuzz test draws: ``nightly`` under
    ``--hypothesis-profile nightly`` (1000 examples by default), a tenth (at least 20) in
    every other run, so that the tiers stay fast and the full counts stay one flag away.
    """
    return max(min(nightly, 20), nightly * settings.default.max_examples // 1000)


class IndependentDynamics:
    """Inverse-dynamics residual computed with Pinocchio alone, from the wire data.

    The model is parsed straight from the file (no Poise code), the wire state
    converted by hand, and the contact Jacobians taken from Pinocchio's frame
    Jacobians: ``rnea(q, v, a) − [0; τ] − Σ J_cᵀ w`` with the per-contact
    wrenches; :attr:`point_force_mismatch` checks the per-point forces give
    the same generalized force.
    """

    def __init__(self, path: str, welcome: Welcome):
        self.model = pin.buildModelFromMJCF(path)
        assert self.model.joints[1].shortname() == "JointModelFreeFlyer"
        self.data = self.model.createData()
        self.welcome = welcome

    def residual(self, state: State, command: Command) -> float:
        rotation = Rotation.from_quat(state.orientation_base_in_world_xyzw).as_matrix()
        q = np.concatenate(
            [
                state.position_base_in_world,
                state.orientation_base_in_world_xyzw
                / np.linalg.norm(state.orientation_base_in_world_xyzw),
                state.joint_position,
            ]
        )
        q = pin.normalize(self.model, q)
        v_local = rotation.T @ state.linear_velocity_base_in_world
        omega = state.angular_velocity_base_in_base
        v = np.concatenate([v_local, omega, state.joint_velocity])
        a_local = rotation.T @ command.base_linear_acceleration_in_world - np.cross(omega, v_local)
        a = np.concatenate(
            [a_local, command.base_angular_acceleration_in_base, command.joint_acceleration]
        )
        generalized = pin.rnea(self.model, self.data, q, v, a).copy()
        generalized[6:] -= command.joint_torque
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        wrenches = command.contact_wrench_in_world.reshape(-1, 6)
        point_forces = command.contact_force_in_world.reshape(-1, 3)
        from_points = np.zeros_like(generalized)
        from_wrenches = np.zeros_like(generalized)
        index = 0
        for contact, wrench in zip(self.welcome.contacts, wrenches, strict=True):
            frame_id = self.model.getFrameId(contact.frame)
            jacobian = pin.getFrameJacobian(
                self.model, self.data, frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )
            from_wrenches += jacobian.T @ wrench
            rotation_frame = self.data.oMf[frame_id].rotation
            for point in contact.points_in_frame:
                offset = rotation_frame @ np.array(point)
                point_jacobian = jacobian[:3] - pin.skew(offset) @ jacobian[3:]
                from_points += point_jacobian.T @ point_forces[index]
                index += 1
        generalized -= from_wrenches
        # Distributed mode: the point forces and the per-contact wrenches agree
        # (measured mode sends no point forces).
        self.point_force_mismatch = (
            float(np.abs(from_points - from_wrenches).max()) if point_forces.any() else 0.0
        )
        return float(np.abs(generalized).max())


REVOLUTE_CROUCH = {
    f"{side}_{joint}": [angle]
    for side in ("left", "right")
    for joint, angle in (("hip_pitch", -0.3), ("knee", 0.6), ("ankle_pitch", -0.3))
}
"""The revolute humanoid's legs slightly bent (hips and ankles −0.3 rad, knees 0.6 rad), by its
own joint names: the jump and walk scenarios name the thesis humanoid's."""


def base_tilt_deg(state) -> float:
    """Angle between a simulator state's base z axis and the world's vertical (degrees)."""
    rotation = pin.Quaternion(np.array(state.orientation_base_in_world_xyzw)).toRotationMatrix()
    return float(np.degrees(np.arccos(np.clip(rotation[2, 2], -1.0, 1.0))))


POISE = [sys.executable, "-m", "controller_server.cli"]
"""What the ``poise`` script runs."""


def run_poise(
    arguments: list[str], cwd: Path, timeout_s: float = 90.0
) -> subprocess.CompletedProcess:
    """``poise ARGUMENTS`` in a subprocess in ``cwd``, no stdin, bounded by ``timeout_s``."""
    return subprocess.run(
        [*POISE, *arguments],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout_s,
        stdin=subprocess.DEVNULL,
    )


CAPTION_ROWS = 30
"""A video's caption band at the top (its time changes every frame: not motion)."""


def video_frames(path: Path) -> list[np.ndarray]:
    """Every frame of the MP4, RGB, the caption band cut off."""
    with av.open(str(path)) as container:
        return [
            frame.to_ndarray(format="rgb24")[CAPTION_ROWS:]
            for frame in container.decode(container.streams.video[0])
        ]


def red_pixels(image: np.ndarray) -> int:
    """Pixels of the push arrow's red (nothing else in the scene is red)."""
    r, g, b = (image[..., channel].astype(int) for channel in range(3))
    return int(np.count_nonzero((r > 150) & (r > 2 * g) & (r > 2 * b)))


def yellow_pixels(image: np.ndarray) -> int:
    """Pixels of the support polygon's yellow."""
    r, g, b = (image[..., channel].astype(int) for channel in range(3))
    return int(np.count_nonzero((r > 150) & (g > 120) & (b < 0.5 * g)))


def moved(first: np.ndarray, later: np.ndarray) -> int:
    """Pixels that changed by more than the encoder's noise."""
    return int(np.count_nonzero(np.abs(first.astype(int) - later.astype(int)).max(axis=2) > 40))


def box_stl(size_m) -> bytes:
    """A binary STL of a box of ``size_m`` (x, y, z) centred on the origin."""
    half = np.asarray(size_m) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    faces = [
        (0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
        (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3),
    ]  # fmt: skip
    record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
    triangles = np.zeros(len(faces), dtype=record)
    triangles["vertices"] = corners[np.array(faces)]
    return b"\0" * 80 + np.uint32(len(faces)).tobytes() + triangles.tobytes()
