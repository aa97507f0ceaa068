"""The bridge loop against a real server and emulated actuators: start-up, faults, safety.

Each test opens a bridge with emulation (MIT-mode actuators on virtual CAN
channels, the revolute_humanoid in the reference simulator) and drives it
tick by tick, injecting faults into the emulated actuators between ticks;
what reached each actuator is read from the emulated motors' own logs.
"""

from __future__ import annotations

import queue
from pathlib import Path

import numpy as np
import pytest

from clients.bridge.app import open_bridge
from clients.bridge.config import BridgeConfigError, load_bridge_config
from clients.bridge.loop import BridgeStartError
from protocol.messages import Command

pytestmark = pytest.mark.e2e

EXAMPLE = Path(__file__).parents[3] / "examples" / "bridge" / "revolute_humanoid_mit.toml"


def example(**bridge):
    config = load_bridge_config(EXAMPLE)
    settings = config.bridge.model_copy(update=bridge)
    return config.model_copy(update={"bridge": settings})


def ticks(session, count):
    bridge = session.bridge
    for _ in range(count):
        bridge.tick()
        bridge.pacer.wait()


def test_start_up_reads_every_actuator_with_zero_commands_before_enabling(server):
    with open_bridge(example(), server.endpoint, emulate=True) as session:
        bridge = session.bridge
        bridge.start()
        plant_q = bridge.joint_map.motor_position_rad(
            session.emulation.plant.backend.state().joint_position
        )
        for i, (name, motor) in enumerate(session.emulation.motors.items()):
            kinds = [record.kind for record in motor.received]
            first_enable = kinds.index("enable")
            before = list(motor.received)[:first_enable]  # a disabled MIT motor applies nothing
            assert all(r.command.torque_Nm == 0 and r.command.kp_Nm_per_rad == 0 for r in before)
            after = [r for r in list(motor.received)[first_enable + 1 :] if r.kind != "enable"]
            assert after and after[0].kind == "safe", name  # zero torque once enabled: no kick
            assert bridge.report.links[i].replies == 2, name  # read, then read after enabling
        np.testing.assert_allclose(  # the positions were read (16-bit quantized)
            bridge.joint_map.motor_position_rad(bridge.joint_position_rad), plant_q, atol=4e-4
        )
        ticks(session, 50)
        assert bridge.report.commands == 50
        assert not bridge.latch.latched
        bridge.shutdown()
        assert all(m.received[-1].kind == "disable" for m in session.emulation.motors.values())


def test_a_silent_actuator_refuses_the_start_naming_it(server):
    with open_bridge(example(), server.endpoint, emulate=True) as session:
        session.emulation.motors["left_knee"].silent = True
        with pytest.raises(
            BridgeStartError, match=r"no reply from left_knee \(bus 'left_leg', id 4\)"
        ):
            session.bridge.start()
        assert not any(
            record.kind == "enable"
            for motor in session.emulation.motors.values()
            for record in motor.received
        )


def test_an_actuator_going_silent_latches_the_safe_state_until_rearmed(server):
    operator: queue.Queue[str] = queue.Queue()
    with open_bridge(example(), server.endpoint, emulate=True, operator=operator) as session:
        bridge = session.bridge
        bridge.start()
        ticks(session, 20)
        knee = session.emulation.motors["left_knee"]
        knee.silent = True
        ticks(session, bridge.settings.max_missed_replies)
        assert bridge.latch.latched
        assert (
            "left_knee's actuator (bus 'left_leg', id 4) did not answer 5 ticks"
            in (bridge.report.latches[0])
        )
        ticks(session, 20)  # it stays safe: kp = 0, τ = 0, damping only
        for name, motor in session.emulation.motors.items():
            if motor is knee:  # silent: takes nothing
                continue
            later = list(motor.received)[-21:]  # the latching tick and 20 more
            assert all(r.kind == "safe" and r.command.kd_Nm_s_per_rad > 0 for r in later), name
            assert motor.received[-22].command.kd_Nm_s_per_rad == 0, name  # a torque command
        knee.silent = False
        operator.put("rearm")
        bridge._operator_commands()
        assert not bridge.latch.latched
        ticks(session, 20)
        assert knee.received[-1].kind == "command" and bridge.report.commands > 20
        bridge.shutdown()


def test_an_actuator_fault_latches_naming_the_joint_and_the_fault(server):
    with open_bridge(example(), server.endpoint, emulate=True) as session:
        bridge = session.bridge
        bridge.start()
        ticks(session, 10)
        session.emulation.motors["right_ankle_pitch"].fault_code = 1
        ticks(session, 2)
        assert bridge.latch.latched
        assert "right_ankle_pitch's actuator" in bridge.report.latches[0]
        assert "fault" in bridge.report.latches[0]
        bridge.shutdown()


def test_non_finite_torques_from_the_server_never_reach_an_actuator(server, monkeypatch):
    with open_bridge(example(), server.endpoint, emulate=True) as session:
        bridge = session.bridge
        bridge.start()
        ticks(session, 10)
        receive = bridge.client.receive_command

        def corrupted() -> Command:
            command = receive()
            torque = np.array(command.joint_torque)
            torque[3] = np.nan
            return command.model_copy(update={"joint_torque": torque})

        monkeypatch.setattr(bridge.client, "receive_command", corrupted)
        start = session.emulation.motors["left_knee"].received[-1].time_s
        ticks(session, 3)
        assert bridge.report.invalid_commands == 3
        for motor in session.emulation.motors.values():
            torques = [r.command.torque_Nm for r in motor.received if r.time_s > start]
            assert np.isfinite(torques).all()
        ticks(session, round(bridge.settings.watchdog_s * bridge.settings.rate_hz) + 2)
        assert bridge.latch.latched and "watchdog" in bridge.report.latches[0]
        bridge.shutdown()


def test_torques_beyond_the_derated_limit_are_clamped_and_counted(server):
    with open_bridge(example(), server.endpoint, emulate=True) as session:
        bridge = session.bridge
        bridge.start()
        ankle = session.emulation.motors["left_ankle_pitch"]
        ankle.temperature_C = 89.0  # 1 °C below its limit: derated to 5 %
        ticks(session, 30)
        limit = bridge.joint_map.torque_limit_Nm[bridge.joint_map.names.index("left_ankle_pitch")]
        applied = [abs(r.command.torque_Nm) for r in list(ankle.received)[-20:]]
        assert max(applied) <= 0.05 * limit + 0.1
        assert bridge.report.clamped_torques > 0
        ankle.temperature_C = 90.0
        ticks(session, 2)
        assert (
            "left_ankle_pitch's motor at 90 °C reached its limit 90 °C" in bridge.report.latches[0]
        )
        bridge.shutdown()


def test_an_operator_estop_holds_safe_then_disables_every_actuator(server):
    operator: queue.Queue[str] = queue.Queue()
    with open_bridge(example(), server.endpoint, emulate=True, operator=operator) as session:
        operator.put("estop")
        report = session.bridge.run(duration_s=1.0)
        assert report.stopped == "estop" and report.latches == ["e-stop: operator"]
        for motor in session.emulation.motors.values():
            assert [r.kind for r in motor.received][-2:] == ["safe", "disable"]


def test_a_map_for_another_robot_is_refused_naming_the_joints(server):
    config = example(model="thesis_humanoid")
    with pytest.raises(BridgeConfigError, match="the actuator map does not match thesis_humanoid"):
        with open_bridge(config, server.endpoint, emulate=True):
            pass


def test_a_bus_that_fails_latches_once_and_the_other_buses_hold_safe(server, caplog):
    with open_bridge(example(), server.endpoint, emulate=True) as session:
        bridge = session.bridge
        bridge.start()
        ticks(session, 10)
        bridge.buses["right_leg"]._bus.shutdown()  # the interface goes down
        with caplog.at_level("ERROR", logger="poise.bridge"):
            ticks(session, 10)
        assert bridge.latch.latched and "bus 'right_leg'" in bridge.report.latches[0]
        lines = [record.getMessage() for record in caplog.records]
        assert len(lines) == 2, lines  # the latch, and the bus that cannot hold safe: once each
        assert lines[0].startswith("safe state latched: bus 'right_leg'")
        for joint, motor in session.emulation.motors.items():
            if not joint.startswith("right_") or "shoulder" in joint or "elbow" in joint:
                assert motor.received[-1].kind == "safe", joint  # the working buses
        bridge.shutdown()
