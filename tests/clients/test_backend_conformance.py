"""One conformance suite, run over every physics backend (reference simulator and MuJoCo)."""

import numpy as np
import pinocchio as pin
import pytest

from clients import ControllerClient
from clients.physics.model_file import builtin_model_path
from clients.physics.status import standing_state
from clients.sim.runner import make_backend
from clients.sim.scenario import Scenario
from clients.state import RobotState

pytestmark = pytest.mark.e2e

BACKENDS = ["reference", "mujoco"]
GRAVITY = 9.81

CHAIN_MJCF = """
<mujoco model="chain">
  <compiler angle="radian"/>
  <option timestep="0.001" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" contype="0" conaffinity="1"/>
    <body name="pelvis" pos="0 0 30">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="2" diaginertia="0.02 0.02 0.02"/>
      <geom type="box" size="0.05 0.05 0.05" contype="1" conaffinity="0"/>
      <body name="link1" pos="0 0 -0.05">
        <joint name="j1" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 -0.2" mass="1" diaginertia="0.014 0.014 0.001"/>
        <geom type="box" size="0.03 0.03 0.2" pos="0 0 -0.2" contype="1" conaffinity="0"/>
        <body name="link2" pos="0 0 -0.4">
          <joint name="j2" type="ball"/>
          <inertial pos="0 0 -0.2" mass="1" diaginertia="0.014 0.014 0.001"/>
          <geom type="box" size="0.03 0.03 0.2" pos="0 0 -0.2" contype="1" conaffinity="0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="j1" gear="1" ctrllimited="true" ctrlrange="-10 10"/>
    <motor joint="j2" gear="1 0 0 0 0 0" ctrllimited="true" ctrlrange="-10 10"/>
    <motor joint="j2" gear="0 1 0 0 0 0" ctrllimited="true" ctrlrange="-10 10"/>
    <motor joint="j2" gear="0 0 1 0 0 0" ctrllimited="true" ctrlrange="-10 10"/>
  </actuator>
</mujoco>
"""


def backend_for(name, model, **kwargs):
    scenario = Scenario(name="conformance", model=str(model), backend=name, **kwargs)
    return make_backend(scenario)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_passive_model_falls_as_free_fall_predicts(backend_name):
    backend = backend_for(backend_name, "thesis_humanoid")
    joints = 39
    start = RobotState(
        joint_position=np.tile([0.0, 0.0, 0.0, 1.0], 13),
        joint_velocity=np.zeros(joints),
        position_base_in_world=np.array([0.0, 0.0, 1.5]),
        orientation_base_in_world_xyzw=np.array([0.0, 0.0, 0.0, 1.0]),
        linear_velocity_base_in_world=np.zeros(3),
        angular_velocity_base_in_base=np.zeros(3),
    )
    backend.reset(start)
    # The soles start 0.56 m up (standing height 0.945 m): contact after √(2·0.56/g) ≈ 0.34 s.
    dt = backend.timestep_s
    for _ in range(250):
        backend.step(np.zeros(joints), [])
        t = backend.time_s
        z = backend.state().position_base_in_world[2]
        # Semi-implicit Euler is exactly z₀ − g t (t + Δt) / 2, within g t Δt / 2 of the curve.
        assert z == pytest.approx(1.5 - 0.5 * GRAVITY * t * (t + dt), abs=1e-6)
        assert abs(z - (1.5 - 0.5 * GRAVITY * t**2)) <= 0.5 * GRAVITY * t * dt + 1e-6
        assert backend.contact_flags() == [False, False]


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_frictionless_swinging_chain_conserves_energy(backend_name, tmp_path):
    """A passive chain swinging in free fall: kinetic + potential energy stays put."""
    path = tmp_path / "chain.xml"
    path.write_text(CHAIN_MJCF)
    backend = backend_for(backend_name, path, friction_coefficient=0.01)
    model = pin.buildModelFromMJCF(str(path))
    data = model.createData()
    backend.reset(
        RobotState(
            joint_position=np.array(
                [0.8, *pin.Quaternion(pin.rpy.rpyToMatrix(0.3, 0.5, 0.0)).coeffs()]
            ),
            joint_velocity=np.array([1.0, 0.5, -0.7, 0.2]),
            position_base_in_world=np.array([0.0, 0.0, 30.0]),
            orientation_base_in_world_xyzw=np.array([0.0, 0.0, 0.0, 1.0]),
            linear_velocity_base_in_world=np.zeros(3),
            angular_velocity_base_in_base=np.array([0.2, 0.0, 0.1]),
        )
    )

    def energy():
        s = backend.state()
        rotation = pin.Quaternion(s.orientation_base_in_world_xyzw).toRotationMatrix()
        q = np.concatenate(
            [s.position_base_in_world, s.orientation_base_in_world_xyzw, s.joint_position]
        )
        v = np.concatenate(
            [
                rotation.T @ s.linear_velocity_base_in_world,
                s.angular_velocity_base_in_base,
                s.joint_velocity,
            ]
        )
        return pin.computeKineticEnergy(model, data, q, v) + pin.computePotentialEnergy(
            model, data, q
        )

    initial = energy()
    worst = 0.0
    for _ in range(2000):
        backend.step(np.zeros(4), [])
        worst = max(worst, abs(energy() - initial))
    kinetic_scale = 5.0  # J: the chain's swinging energy is a few joules
    print(f"{backend_name}: max energy drift {worst:.3g} J over 2 s")
    assert worst < 0.02 * (kinetic_scale + GRAVITY * 4.0)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_static_pose_with_server_torques_stays_within_a_millimetre(backend_name, server):
    """The server's tracking controller at the standing pose compensates gravity."""
    backend = backend_for(backend_name, "thesis_humanoid")
    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect("thesis_humanoid", controller="tracking")
        backend.reset(standing_state(welcome, {}))
        positions = []
        for tick in range(2300):
            state = backend.state()
            command = client.step(state.to_message(backend.time_s, backend.contact_flags()))
            backend.step(command.joint_torque, [])
            if tick >= 300:  # the contacts settle (penalty sink) in the first 0.3 s
                positions.append(backend.state().position_base_in_world.copy())
    positions = np.array(positions)
    drift = np.linalg.norm(positions - positions[0], axis=1).max()
    print(f"{backend_name}: base drift {drift * 1e3:.3f} mm over 2 s")
    assert drift < 1e-3
    assert builtin_model_path("thesis_humanoid").is_file()
