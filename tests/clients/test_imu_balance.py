"""Balance without ground truth (issue 17): the base from a simulated IMU, estimated by the server.

The thesis' push scenarios with ``base_state = "imu"``: the simulator sends the joints, the
contact flags and a BMI088-class IMU on the pelvis (white noise, seeded initial biases within
the data sheet's offsets, bias random walk, an AHRS orientation 0.5° off), never the base; the
server's contact-aided invariant EKF estimates the base and the controller balances on the
estimate. Fall detection and the errors below use the simulator's truth.
"""

import pytest

from clients.physics.errors import ScenarioError
from clients.sim.app import run_scenarios
from clients.sim.scenario import load_scenario

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

TILT_ERROR_MAX_DEG = 1.0
VELOCITY_ERROR_RMS_M_PER_S = 0.05
HEIGHT_ERROR_MAX_M = 0.01


@pytest.mark.parametrize("backend", ["reference", "mujoco"])
@pytest.mark.parametrize("controller", ["momentum", "prioritized"])
def test_the_thesis_pushes_are_survived_on_the_estimated_base(
    server, backend, controller, tmp_path
):
    """Issue 17 acceptance: push_sequence and head_push stay up; on push_sequence the
    estimate is within 1° of tilt, 0.05 m/s RMS of velocity and 1 cm of height."""
    reports = run_scenarios(
        ["push_sequence", "head_push"],
        tmp_path,
        endpoint=server.endpoint,
        overrides={"backend": backend, "controller": controller, "base_state": "imu"},
        progress=False,
    )
    for report in reports:
        errors = report["base_estimate_error"]
        print(
            f"{report['scenario']:<14} {backend:<9} {controller:<11} "
            f"{'fell' if report['fell'] else 'stayed up'}: tilt max "
            f"{errors['tilt_error_max_deg']:.2f}° (RMS {errors['tilt_error_rms_deg']:.2f}°), "
            f"velocity RMS {errors['velocity_error_rms_m_per_s']:.4f} m/s, height max "
            f"{100 * errors['height_error_max_m']:.2f} cm, yaw at the end "
            f"{errors['yaw_error_end_deg']:+.1f}°"
        )
    for report in reports:
        assert not report["fell"], report
        assert report["complete"], report
    errors = reports[0]["base_estimate_error"]
    assert reports[0]["scenario"] == "push_sequence"
    assert errors["tilt_error_max_deg"] <= TILT_ERROR_MAX_DEG, errors
    assert errors["velocity_error_rms_m_per_s"] <= VELOCITY_ERROR_RMS_M_PER_S, errors
    assert errors["height_error_max_m"] <= HEIGHT_ERROR_MAX_M, errors


def test_an_imu_scenario_refuses_what_it_cannot_simulate():
    with pytest.raises(ScenarioError, match="must equal control_rate_hz"):
        load_scenario("stand", base_state="imu", imu={"rate_hz": 500.0})
    with pytest.raises(ScenarioError, match="command_delay_ticks = 0"):
        load_scenario("stand", base_state="imu", command_delay_ticks=1)
    with pytest.raises(ScenarioError, match="did you mean 'pelvis'"):
        load_scenario("stand", base_state="imu", imu={"body": "pelvsi"})
