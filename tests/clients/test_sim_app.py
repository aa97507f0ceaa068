"""Scenarios, the runner over ZeroMQ, metrics and plots (MuJoCo backend)."""

import json

import numpy as np
import pytest
from pydantic import ValidationError

from clients.physics.status import support_flags
from clients.sim.app import run_scenarios
from clients.sim.metrics import strictly_inside
from clients.sim.scenario import SCENARIO_DIR, Scenario, load_scenario

pytestmark = pytest.mark.e2e


@pytest.mark.parametrize("path", sorted(SCENARIO_DIR.glob("*.toml")), ids=lambda p: p.stem)
def test_builtin_scenarios_validate(path):
    scenario = load_scenario(path.stem)
    assert scenario.name == path.stem
    assert scenario.physics_steps_per_control_tick >= 1


def test_scenario_errors_are_explicit():
    with pytest.raises(FileNotFoundError, match="push_sequence"):
        load_scenario("no_such_scenario")
    with pytest.raises(ValidationError, match="whole multiple"):
        Scenario(name="x", control_rate_hz=300.0, physics_rate_hz=1000.0)
    with pytest.raises(ValidationError):
        Scenario(name="x", friction_coefficient=-1.0)


def test_strictly_inside():
    square = np.array([[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]])  # counter-clockwise
    assert strictly_inside(np.array([0.0, 0.0]), square)
    assert not strictly_inside(np.array([0.0995, 0.0]), square)  # within the 1 mm margin
    assert not strictly_inside(np.array([0.2, 0.0]), square)
    assert not strictly_inside(np.array([np.nan, 0.0]), square)


def test_quiet_standing_in_mujoco_stays_up_with_report_and_plot(server, tmp_path):
    reports = run_scenarios(
        ["stand"],
        tmp_path,
        endpoint=server.endpoint,
        overrides={"backend": "mujoco", "duration_s": 0.5},
        progress=False,
    )
    (report,) = reports
    assert not report["fell"]
    # The linear momentum objective moves the CM from over the ankles toward the
    # middle of the feet (c_des, 6 cm ahead), slowly: a few centimetres in 0.5 s.
    assert report["com_excursion_m"] < 0.05
    assert report["cop_strictly_inside_fraction"] > 0.9
    assert report["simulated_s"] == pytest.approx(0.5)
    assert json.loads((tmp_path / "report.json").read_text())[0]["scenario"] == "stand"
    png = (tmp_path / "stand.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000


def test_param_changes_must_be_in_time_order():
    with pytest.raises(ValidationError, match="time order"):
        Scenario(
            name="x",
            param_changes=[{"time_s": 2.0, "params": {}}, {"time_s": 1.0, "params": {}}],
        )


def test_a_touching_foot_supports_once_loaded_until_it_lifts_off():
    threshold_N = 20.0
    flags = [True, False]
    # The left foot stays a support while touching, however light; the right foot
    # touches but carries 5 N: not yet a support.
    flags = support_flags(flags, [True, True], np.array([3.0, 5.0]), threshold_N)
    assert flags == [True, False]
    flags = support_flags(flags, [True, True], np.array([3.0, 25.0]), threshold_N)
    assert flags == [True, True]
    flags = support_flags(flags, [False, True], np.array([0.0, 600.0]), threshold_N)
    assert flags == [False, True]
    flags = support_flags(flags, [True, True], np.array([10.0, 600.0]), threshold_N)
    assert flags == [False, True]


def test_foot_slip_and_rotation_are_measured_only_while_supporting(server):
    """A supporting foot that slides 5 cm and yaws 0.1 rad is reported; a lifted one is not."""
    from clients import ControllerClient
    from clients.physics.status import standing_state
    from clients.sim.metrics import _foot_slip_and_rotation
    from clients.sim.runner import RunRecord

    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        welcome = client.connect("thesis_humanoid")
    still = standing_state(welcome, {})
    slid = standing_state(welcome, {})
    slid.position_base_in_world[0] += 0.05
    half_angle = 0.05  # yaw 0.1 rad about z
    slid.orientation_base_in_world_xyzw[:] = [0.0, 0.0, np.sin(half_angle), np.cos(half_angle)]
    record = RunRecord(load_scenario("stand"), welcome)
    record.states = [still, slid]
    record.contact_flags = [[True, True], [True, True]]
    slip_m, rotation_rad = _foot_slip_and_rotation(record)
    # 5 cm of slide plus the yaw's sweep of a sole frame ≤ 11 cm from the base: ±1.1 cm.
    assert 0.039 < slip_m < 0.061
    assert rotation_rad == pytest.approx(0.1, rel=1e-9)
    record.contact_flags = [[True, True], [False, False]]
    assert _foot_slip_and_rotation(record) == (0.0, 0.0)


def test_push_sweep_bisects_each_direction_and_waits_for_the_robot_to_settle(
    monkeypatch, capsys, tmp_path
):
    """The sweep's bookkeeping, with a stand-in run: a robot survives a push up to a
    direction- and controller-dependent force, and only if the run lasts 3 s past it."""
    import clients.sim.sweep as sweep_module
    from clients.pool import RunPool

    limits = {("momentum", 1.0): 300.0, ("momentum", -1.0): 150.0, ("prioritized", -1.0): 260.0}
    durations = set()

    class Run:
        def __init__(self, scenario, endpoint, curve=None):
            (push,) = scenario.pushes
            force_x = push.force_in_world_N[0]
            params = scenario.params
            # Tracking only gives up half of the momentum controller's margin.
            scale = 0.5 if params.get("weight_linear_momentum") == 0.0 else 1.0
            limit = limits.get((scenario.controller, np.sign(force_x)), 200.0) * scale
            durations.add(scenario.duration_s)
            self.fell = abs(force_x) > limit
            self.stopped = self.fall_reason = ""

    monkeypatch.setattr(sweep_module, "run_scenario", Run)
    push = sweep_module.PushSpec(
        body="chest", force_in_world_N=(1, 0, 0), start_s=0.5, duration_s=0.1
    )
    directions = {"behind": (2.0, 0.0, 0.0), "front": (-1.0, 0.0, 0.0)}
    with RunPool(endpoint="tcp://unused") as pool:
        sweep = sweep_module.sweep_controllers(
            "stand", push, directions, pool, output_dir=tmp_path, progress=False
        )
    results = sweep.largest_survived_N()

    assert durations == {0.5 + 0.1 + 3.0}  # stand lasts 2 s: extended to settle
    assert results["tracking only"]["behind"] == pytest.approx(150.0, abs=5.0)
    assert results["tracking only"]["front"] == pytest.approx(75.0, abs=5.0)
    assert results["+ linear momentum"]["front"] == pytest.approx(150.0, abs=5.0)
    assert results["prioritized (de Lasa 2010)"]["front"] == pytest.approx(260.0, abs=5.0)
    table = capsys.readouterr().out
    assert "weakest" in table and "2.00×" in table  # + linear momentum: 150 / 75
    # Each bisection: 2000 N fells, then halving to 5 N: 10 trials, the answer the
    # largest force survived, every smaller force survived and every larger one fell.
    bisection = sweep.bisections["tracking only"]["front"]
    assert [force for force, _ in bisection.trials][:3] == [2000.0, 1000.0, 500.0]
    assert len(bisection.trials) == bisection.max_trials == 10
    assert all(ok == (force <= 75.0) for force, ok in bisection.trials)
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["largest_survived_N"] == results
    assert written["trials"]["tracking only"]["front"][0] == {"force_N": 2000.0, "survived": False}
    png = (tmp_path / "sweep_stand.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000


@pytest.mark.parametrize("delay", [0, 1])
def test_command_delay_holds_each_command_from_the_next_tick(server, monkeypatch, delay):
    """Lockstep applies tick k's command at tick k; pipelined at tick k + 1 (tick 0's at 0)."""
    import clients.sim.runner as runner

    applied = []
    make_backend = runner.make_backend

    def recording_backend(scenario):
        backend = make_backend(scenario)
        step = backend.step

        def recorded_step(joint_torque, pushes):
            applied.append(np.array(joint_torque))
            return step(joint_torque, pushes)

        backend.step = recorded_step
        return backend

    monkeypatch.setattr(runner, "make_backend", recording_backend)
    scenario = load_scenario("stand", backend="mujoco", duration_s=0.05, command_delay_ticks=delay)
    record = runner.run_scenario(scenario, server.endpoint)
    sent = [command.joint_torque for command in record.commands]
    assert len(applied) == len(sent) == 50
    expected = sent if delay == 0 else [sent[0], *sent[:-1]]
    for torque, command_torque in zip(applied, expected, strict=True):
        np.testing.assert_array_equal(torque, command_torque)
    assert not np.array_equal(sent[1], sent[2])  # the commands differ tick to tick


def test_sparse_diagnostics_feed_metrics_and_plots(server, tmp_path):
    """With diagnostics every 5th tick the report and the plot use those ticks only."""
    from clients.sim.metrics import compute_metrics
    from clients.sim.plots import plot_run
    from clients.sim.runner import run_scenario

    scenario = load_scenario("stand", backend="mujoco", duration_s=0.2, diagnostics_period_ticks=5)
    record = run_scenario(scenario, server.endpoint)
    assert record.diagnosed_ticks() == list(range(0, 200, 5))
    assert len(record.diagnostics()) == 40
    metrics = compute_metrics(record)
    assert not metrics["fell"] and 0.0 <= metrics["com_excursion_m"] < 0.05
    assert metrics["cop_strictly_inside_fraction"] > 0.9
    plot_run(record, tmp_path / "sparse.png")
    assert (tmp_path / "sparse.png").stat().st_size > 10_000


def test_an_initial_crouch_keeps_the_soles_on_the_ground():
    """``initial_joint_position`` bends the legs; the base comes down so the soles touch z = 0
    (it once kept the straight pose's height, and the robot started 4 cm in the air)."""
    import pinocchio as pin

    from clients.physics.model_file import describe_model
    from clients.physics.status import standing_state
    from controller_server.session import Session
    from protocol.messages import Hello

    welcome = Session(Hello(model="revolute_humanoid")).welcome(0)
    model = describe_model("revolute_humanoid").model
    crouch = {
        f"{side}_{joint}": [angle]
        for side in ("left", "right")
        for joint, angle in (("hip_pitch", -0.3), ("knee", 0.6), ("ankle_pitch", -0.3))
    }
    state = standing_state(welcome, crouch, model)
    q = np.concatenate(
        [state.position_base_in_world, state.orientation_base_in_world_xyzw, state.joint_position]
    )
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    heights = [
        data.oMf[model.getFrameId(contact.frame)].act(np.array(point))[2]
        for contact in welcome.contacts
        for point in contact.points_in_frame
    ]
    assert min(heights) == pytest.approx(0.0, abs=1e-12)
    assert welcome.standing_position_base_in_world[2] - state.position_base_in_world[2] > 0.03
    # Without the model (the bridge's emulation), the pose keeps the standing base.
    assert standing_state(welcome, crouch).position_base_in_world[2] == pytest.approx(
        welcome.standing_position_base_in_world[2]
    )
