"""The actuator map: validation, the match with the server's joints, gearing and limits."""

from pathlib import Path

import numpy as np
import pytest

from clients.bridge.config import (
    BridgeConfig,
    BridgeConfigError,
    check_against_welcome,
    load_bridge_config,
)
from clients.bridge.joint_map import JointMap
from clients.bridge.safety import InvalidCommand, check_joints, clamp_torque
from protocol.messages import JointInfo, Welcome

EXAMPLE = Path(__file__).parents[3] / "examples" / "bridge" / "revolute_humanoid_mit.toml"


def welcome(*names: str) -> Welcome:
    return Welcome(
        session_id="s",
        model_name="robot",
        model_hash="h",
        total_mass=10.0,
        standing_position_base_in_world=(0.0, 0.0, 1.0),
        joints=[
            JointInfo(
                name=name,
                kind="revolute",
                nq=1,
                nv=1,
                torque_limit=[50.0],
                position_lower=[-1.0],
                position_upper=[1.0],
            )
            for name in names
        ],
        contacts=[],
        controller="momentum",
        params={},
    )


def config(**joints) -> BridgeConfig:
    return BridgeConfig.model_validate({"buses": {"can0": {"protocol": "mit"}}, "joints": joints})


def write(tmp_path, text: str) -> Path:
    path = tmp_path / "map.toml"
    path.write_text(text)
    return path


def test_the_example_map_loads():
    loaded = load_bridge_config(EXAMPLE)
    assert len(loaded.joints) == 22
    assert set(loaded.buses) == {"left_leg", "right_leg", "left_arm", "right_arm"}


def test_a_typo_gets_the_closest_key_of_its_own_table(tmp_path):
    path = write(
        tmp_path,
        '[buses.a]\nprotocol = "mit"\n[joints.knee]\nbus = "a"\nid = 1\ngear_ration = 2\n',
    )
    with pytest.raises(
        BridgeConfigError, match=r"joints.knee.gear_ration.*did you mean 'gear_ratio'"
    ):
        load_bridge_config(path)


MIT_KNEE = '[buses.a]\nprotocol = "mit"\n[joints.knee]\nbus = "a"\nid = 1\n'


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (MIT_KNEE + "gear_ratio = inf\n", r"joints.knee.gear_ratio.*finite"),
        (MIT_KNEE + "zero_offset_rad = nan\n", r"joints.knee.zero_offset_rad.*finite"),
        ("[bridge]\nrate_hz = inf\n" + MIT_KNEE, r"bridge.rate_hz"),
        (
            "[bridge]\nrate_hz = 500\n[emulation]\nphysics_rate_hz = 2100\n" + MIT_KNEE,
            r"physics_rate_hz \(2100\) must be a whole multiple of bridge.rate_hz \(500\)",
        ),
    ],
    ids=["infinite gear", "nan offset", "infinite rate", "physics rate not a multiple"],
)
def test_numbers_a_map_cannot_mean_are_refused_in_one_line(tmp_path, text, expected):
    """Issue 32 (10): these passed validation, then failed on the bus or in the emulator."""
    with pytest.raises(BridgeConfigError, match=expected) as error:
        load_bridge_config(write(tmp_path, text))
    assert "\n" not in str(error.value)


def test_a_binary_file_is_not_a_map(tmp_path):
    path = tmp_path / "map.toml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(BridgeConfigError, match=r"is not text .* not UTF-8"):
        load_bridge_config(path)


def test_a_joint_on_a_missing_bus_and_a_shared_id_are_refused():
    with pytest.raises(ValueError, match="no such bus; buses: can0"):
        config(knee={"bus": "can1", "id": 1})
    with pytest.raises(ValueError, match="share id 1 on bus 'can0'"):
        config(knee={"bus": "can0", "id": 1}, hip={"bus": "can0", "id": 1})


def test_a_damiao_actuator_needs_its_master_id():
    with pytest.raises(ValueError, match="needs master_id"):
        BridgeConfig.model_validate(
            {"buses": {"a": {"protocol": "damiao"}}, "joints": {"knee": {"bus": "a", "id": 1}}}
        )


def test_the_host_watchdog_must_act_before_the_actuators_own():
    with pytest.raises(ValueError, match="must exceed watchdog_s"):
        BridgeConfig.model_validate(
            {
                "bridge": {"watchdog_s": 0.2, "actuator_watchdog_s": 0.1},
                "buses": {},
                "joints": {},
            }
        )


def test_a_map_that_does_not_match_the_servers_joints_names_them():
    mapped = config(hip={"bus": "can0", "id": 1}, knee_typo={"bus": "can0", "id": 2})
    with pytest.raises(BridgeConfigError) as error:
        check_against_welcome(mapped, welcome("hip", "knee", "ankle"))
    message = str(error.value)
    assert "no actuator for knee, ankle" in message
    assert "has no joint knee_typo" in message
    check_against_welcome(config(a={"bus": "can0", "id": 1}), welcome("a"))


def test_gearing_round_trips_and_conserves_power():
    mapped = config(
        a={"bus": "can0", "id": 1, "gear_ratio": 9.0, "direction": -1, "zero_offset_rad": 0.3},
        b={"bus": "can0", "id": 2},
    )
    joint_map = JointMap(mapped, welcome("a", "b"))
    rng = np.random.default_rng(0)
    q, v, tau = rng.normal(size=(3, 2))
    np.testing.assert_allclose(joint_map.joint_position_rad(joint_map.motor_position_rad(q)), q)
    motor_v = joint_map.motor_velocity_rad_s(v)
    motor_tau = joint_map.motor_torque_Nm(tau)
    np.testing.assert_allclose(motor_v * motor_tau, v * tau)  # lossless gear
    assert motor_v[0] == pytest.approx(-9.0 * v[0])
    assert joint_map.motor_position_rad(np.array([0.3, 0.0]))[0] == pytest.approx(0.0)
    assert joint_map.motor_damping(2.0)["can0"] == {1: pytest.approx(2.0 / 81), 2: 2.0}


def test_limits_default_to_the_models_and_derate_with_temperature():
    mapped = config(
        a={
            "bus": "can0",
            "id": 1,
            "torque_limit_Nm": 20.0,
            "derate_above_C": 60,
            "temperature_limit_C": 80,
        },
        b={"bus": "can0", "id": 2, "position_limit_rad": [-0.5, 0.5]},
    )
    joint_map = JointMap(mapped, welcome("a", "b"))
    np.testing.assert_array_equal(joint_map.torque_limit_Nm, [20.0, 50.0])
    np.testing.assert_array_equal(joint_map.position_upper_rad, [1.0, 0.5])
    derated = joint_map.derated_torque_limit_Nm(np.array([70.0, np.nan]))
    np.testing.assert_allclose(derated, [10.0, 50.0])
    assert joint_map.derated_torque_limit_Nm(np.array([85.0, 20.0]))[0] == 0.0


def test_torques_are_clamped_and_counted_and_non_finite_ones_refused():
    limit = np.array([10.0, 5.0])
    torque, clamped = clamp_torque([12.0, -3.0], limit, ["a", "b"])
    np.testing.assert_array_equal(torque, [10.0, -3.0])
    assert clamped == ["a"]
    with pytest.raises(InvalidCommand, match="not finite at b=nan"):
        clamp_torque([1.0, float("nan")], limit, ["a", "b"])
    with pytest.raises(InvalidCommand, match="3 entries, the robot 2 joints"):
        clamp_torque([1.0, 2.0, 3.0], limit, ["a", "b"])


def test_joint_checks_name_the_joint_and_the_value():
    joint_map = JointMap(
        config(a={"bus": "can0", "id": 1}, b={"bus": "can0", "id": 2}), welcome("a", "b")
    )
    zeros, cool = np.zeros(2), np.array([30.0, np.nan])
    assert check_joints(joint_map, zeros, zeros, cool) == ""
    assert "b at 1.020 rad is outside" in check_joints(joint_map, np.array([0, 1.02]), zeros, cool)
    assert check_joints(joint_map, np.array([0, 1.02]), zeros, cool, margin_rad=0.05) == ""
    assert "a at 25.00 rad/s" in check_joints(joint_map, zeros, np.array([25.0, 0]), cool)
    assert "a's motor at 95 °C" in check_joints(joint_map, zeros, zeros, np.array([95.0, 20]))


def test_bus_time_counts_the_frames_on_the_wire():
    from clients.bridge.buses import bus_time_per_tick_s
    from clients.bridge.config import BusSpec

    # MIT: a command and a reply of 130 bits each per actuator, at 1 Mbit/s.
    assert bus_time_per_tick_s(BusSpec(protocol="mit"), 6) == pytest.approx(6 * 2 * 130e-6)
    assert bus_time_per_tick_s(BusSpec(protocol="odrive", bitrate=500_000), 2) == (
        pytest.approx(2 * 5 * 130 / 500_000)
    )
    # Dynamixel: sync write 14 + 3n, sync read 14 + n, n status packets of 32 bytes.
    spec = BusSpec(protocol="dynamixel", baudrate=4_000_000)
    assert bus_time_per_tick_s(spec, 10) == pytest.approx(10 * (28 + 4 * 10 + 320) / 4e6)


IMU_EXAMPLE = EXAMPLE.with_name("revolute_humanoid_imu.toml")


def imu_map(tmp_path, bridge: str = 'base_state = "imu"', tables: str = "") -> Path:
    """A one-joint map with ``bridge`` in [bridge] and ``tables`` after it."""
    return write(
        tmp_path,
        f'[bridge]\n{bridge}\n{tables}\n[buses.a]\nprotocol = "mit"\n'
        '[joints.knee]\nbus = "a"\nid = 1\nmotor = "AK80-9"\n',
    )


def test_the_imu_example_is_the_mit_example_with_an_imu():
    imu, mit = load_bridge_config(IMU_EXAMPLE), load_bridge_config(EXAMPLE)
    assert imu.bridge.base_state == "imu" and imu.imu is not None
    assert imu.imu.frame == "pelvis" and imu.imu.source == "emulated"
    assert imu.joints == mit.joints and imu.buses == mit.buses
    assert imu.bridge.model_copy(update={"base_state": "simulator"}) == mit.bridge
    assert imu.emulation.pushes == mit.emulation.pushes


def test_an_imu_base_without_an_imu_table_is_an_emulated_imu_on_the_root_body(tmp_path):
    loaded = load_bridge_config(imu_map(tmp_path))
    assert loaded.imu is None
    assert loaded.imu_settings.frame == "" and loaded.imu_settings.source == "emulated"
    assert loaded.imu_settings.orientation_in_frame_xyzw == (0.0, 0.0, 0.0, 1.0)
    turned = load_bridge_config(
        imu_map(tmp_path, tables="[imu]\norientation_in_frame_xyzw = [0, 0, 2, 2]\n")
    )
    assert turned.imu_settings.orientation_in_frame_xyzw == pytest.approx(
        (0.0, 0.0, 0.5**0.5, 0.5**0.5)
    )


@pytest.mark.parametrize(
    ("bridge", "tables", "message"),
    [
        (
            'base_state = "simulator"',
            '[imu]\nframe = "pelvis"\n',
            r'an \[imu\] table is for base_state = "imu" \(this map has base_state = '
            r'"simulator"\)',
        ),
        ("", "[imu]\n", r'an \[imu\] table is for base_state = "imu"'),  # the default: fixed
        (
            'base_state = "imu"',
            '[imu]\nfram = "pelvis"\n',
            r"unknown key 'imu.fram'; did you mean 'frame'\?",
        ),
        ('base_state = "imu"', '[imu]\nsource = "hardware"\n', r"imu.source: Input should be"),
        ('base_state = "imus"', "", r"bridge.base_state: Input should be 'simulator', 'fixed'"),
        (
            'base_state = "imu"',
            "[imu]\norientation_in_frame_xyzw = [0, 0, 0, 0]\n",
            r"imu.orientation_in_frame_xyzw: a rotation needs a non-zero quaternion",
        ),
        (
            'base_state = "imu"',
            "[imu]\nposition_in_frame = [0, 0, 11]\n",
            r"imu.position_in_frame: the IMU must sit within 10 m of its frame",
        ),
        (
            'base_state = "imu"',
            "[emulation.imu]\nrate = 500\n",
            r"unknown key 'emulation.imu.rate'; did you mean 'rate_hz'\?",
        ),
        (
            'base_state = "imu"',
            '[emulation.imu]\nbody = "torso"\n',
            r"emulation.imu.body: the IMU's mount is \[imu\]'s frame",
        ),
        (
            'base_state = "imu"',
            "[emulation]\nphysics_rate_hz = 1000\nimu = { rate_hz = 2000 }\n",
            r"emulation.imu.rate_hz \(2000\) must not exceed physics_rate_hz \(1000\)",
        ),
    ],
)
def test_a_mistake_about_the_imu_is_one_line(tmp_path, bridge, tables, message):
    with pytest.raises(BridgeConfigError, match=message) as error:
        load_bridge_config(imu_map(tmp_path, bridge, tables))
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("source", "emulate", "imu_source", "message"),
    [
        ("emulated", False, None, r'\[imu\] source = "emulated" is the emulated robot\'s IMU: '),
        ("external", False, None, r'\[imu\] source = "external" needs the robot\'s IMU: pass'),
        ("external", True, None, r'\[imu\] source = "external" needs the robot\'s IMU: pass'),
        ("emulated", True, object(), "an IMU source was given but the map does not use it"),
    ],
)
def test_an_imu_the_run_cannot_have_is_refused_before_connecting(
    tmp_path, source, emulate, imu_source, message
):
    from clients.bridge.app import open_bridge

    loaded = load_bridge_config(imu_map(tmp_path, tables=f'[imu]\nsource = "{source}"\n'))
    unreachable = "tcp://127.0.0.1:1"  # refused before any connection is tried
    with pytest.raises(BridgeConfigError, match=message) as error:
        with open_bridge(loaded, unreachable, emulate=emulate, imu_source=imu_source):
            pass
    assert "\n" not in str(error.value)


def test_an_imu_source_with_another_base_state_is_refused():
    from clients.bridge.app import check_base_state

    with pytest.raises(BridgeConfigError, match="an IMU source was given but the map does not"):
        check_base_state(load_bridge_config(EXAMPLE), True, object())  # type: ignore[arg-type]
    check_base_state(load_bridge_config(EXAMPLE), True, None)
