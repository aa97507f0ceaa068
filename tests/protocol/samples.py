"""Valid sample messages of every type, shared by protocol and server tests."""

import numpy as np

from protocol.errors import ErrorCode
from protocol.messages import (
    Asset,
    AssetReceived,
    Bye,
    Command,
    ContactSpec,
    Diagnostics,
    Error,
    Hello,
    JointInfo,
    Params,
    SessionStats,
    SetParams,
    State,
    Stats,
    WeightedDiagnostics,
    Welcome,
)

FILE = bytes(range(256))
FILE_SHA256 = "40aff2e9d2d8922e47afd4648e6967497158785fbd1da870e7110266bf944880"
"""SHA-256 of :data:`FILE`."""

CONTACT = ContactSpec(name="left_foot", frame="left_sole", points_in_frame=[(0.1, 0.05, 0.0)])


def sample_messages():
    """One valid instance of every message type."""
    return [
        Hello(seq=1, model="thesis_humanoid", params={"stiffness": 50.0}),
        Welcome(
            seq=1,
            session_id="abc",
            model_name="m",
            model_hash="0" * 64,
            total_mass=65.0,
            standing_position_base_in_world=(0.0, 0.0, 1.0),
            standing_joint_position=[0.3],
            joints=[
                JointInfo(
                    name="knee",
                    kind="revolute",
                    nq=1,
                    nv=1,
                    torque_limit=[100.0],
                    position_lower=[0.0],
                    position_upper=[2.0],
                )
            ],
            contacts=[CONTACT],
            controller="tracking",
            params={"stiffness": 50.0, "qp_solver": "daqp", "reference": [0.0, 1.0]},
        ),
        State(
            seq=2,
            time_s=0.5,
            joint_position=[0.1, 0.2],
            joint_velocity=np.array([0.3, -0.4]),
            position_base_in_world=[0.0, 0.0, 1.0],
            orientation_base_in_world_xyzw=[0.0, 0.0, 0.0, 1.0],
            linear_velocity_base_in_world=[0.0, 0.0, 0.0],
            angular_velocity_base_in_base=[0.0, 0.0, 0.0],
            contact_flags=[True, False],
            contact_wrench_in_world=np.arange(12.0),
        ),
        Command(
            seq=2,
            joint_acceleration=[1.0, 2.0],
            base_linear_acceleration_in_world=[0.0, 0.0, 0.0],
            base_angular_acceleration_in_base=[0.0, 0.0, 0.0],
            joint_torque=[3.0, 4.0],
            contact_force_in_world=np.zeros(6),
            contact_wrench_in_world=np.zeros(12),
            diagnostics=Diagnostics(
                compute_time_s=1e-3,
                position_com_in_world=[0.0, 0.0, 0.9],
                velocity_com_in_world=[0.0, 0.0, 0.0],
                linear_momentum=[0.0, 0.0, 0.0],
                angular_momentum=[0.0, 0.0, 0.0],
                linear_momentum_rate_desired=[1.0, 2.0, np.nan],
                linear_momentum_rate_achieved=[1.0, 2.0, 3.0],
                angular_momentum_rate_desired=[0.0, 0.0, 0.0],
                angular_momentum_rate_achieved=[0.0, 0.0, 0.0],
                center_of_pressure=[0.01, 0.0, 0.0],
                centroidal_moment_pivot=[0.0, 0.0, 0.0],
                supports=[True, False],
                support_polygon_xy=[0.1, 0.1, -0.1, 0.1, -0.1, -0.1],
                objective_residuals={"tracking": 0.5},
                constraint_residual=0.0,
                root_wrench_residual=0.0,
                saturated_joints=0,
                weighted=WeightedDiagnostics(
                    optimizer_ran=True,
                    angular_momentum_weight=0.1,
                    objective_condition_number=10.0,
                    schur_condition_number=10.0,
                    objective_damping=1e-3,
                    constraint_damping=0.0,
                ),
            ),
        ),
        SetParams(seq=3, params={"stiffness": 10.0}),
        Params(seq=3, params={"stiffness": 10.0}),
        Stats(seq=4),
        Stats(
            seq=4,
            sessions=[
                SessionStats(
                    session_id="abc",
                    model_name="m",
                    controller="tracking",
                    ticks=3,
                    errors=0,
                    compute_time_p50_s=1e-3,
                    compute_time_p99_s=2e-3,
                    idle_s=0.1,
                )
            ],
        ),
        Bye(seq=5),
        Error(seq=6, code=ErrorCode.BAD_SHAPE, field="joint_position", detail="expected 3"),
        # A sent scene with the files it names (binary: not UTF-8), a keyframe, a named foot.
        Hello(
            seq=7,
            model_text='<mujoco><include file="robot.xml"/></mujoco>',
            model_assets={"robot.xml": b"<mujoco/>", "assets/foot.stl": bytes(range(256))},
            keyframe="home",
            contacts=[ContactSpec(name="left_foot", frame="left_ankle_roll_link")],
        ),
        # The same scene with its mesh by hash, its upload in two chunks, the replies.
        Hello(
            seq=8,
            model_text='<mujoco><include file="robot.xml"/></mujoco>',
            model_assets={"robot.xml": b"<mujoco/>"},
            model_asset_hashes={"assets/foot.stl": FILE_SHA256},
        ),
        Error(
            seq=8,
            code=ErrorCode.ASSETS_MISSING,
            field="model_asset_hashes",
            detail="upload them",
            missing_asset_hashes=[FILE_SHA256],
            max_message_bytes=1_000_000,
        ),
        Asset(seq=9, sha256=FILE_SHA256, size_bytes=256, offset_bytes=0, data=FILE[:100]),
        AssetReceived(seq=9, sha256=FILE_SHA256, received_bytes=100, complete=False),
        Asset(seq=10, sha256=FILE_SHA256, size_bytes=256, offset_bytes=100, data=FILE[100:]),
        AssetReceived(seq=10, sha256=FILE_SHA256, received_bytes=256, complete=True),
    ]
