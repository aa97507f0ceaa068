"""The no-step bound beside each sweep result, and the sweep on another robot (issue 31, item 7).

The bound (Koolen et al. 2012, Pratt et al. 2006) is checked against a hand calculation on a
box robot and against the thesis humanoid's mid-foot figure (issue 39: 26.5 N·s). The sweep
runs through `poise sim` (in this process, with a stand-in for the simulated run, so that the
bookkeeping is what is checked): `--controller` picks what is swept, the push body is the
robot's own, a body it lacks is one line before any trial.
"""

import json
import math
from pathlib import Path
from typing import ClassVar

import pytest

import clients.sim.sweep as sweep_module
from clients.physics.model_file import describe_model
from clients.physics.robot_terms import RobotTermsError, no_step_bound
from controller_server.cli import main

VENDOR = str(Path(__file__).parents[1] / "models" / "vendor_humanoid" / "scene.xml")

# A box on two legs, feet 20 × 10 cm set 3 cm forward, hip width 20 cm; every height from the
# soles (z = 0): feet 0–2 cm (1 kg each), legs 5–45 cm (2 kg each), trunk 45–55 cm (20 kg).
BOX_ROBOT = """<mujoco><worldbody>
<body name="trunk" pos="0 0 0.5"><freejoint/>
  <geom type="box" size="0.1 0.15 0.05" mass="20"/>
  <body name="left_leg" pos="0 0.1 -0.25"><joint name="left_hip" axis="0 1 0"/>
    <geom type="box" size="0.02 0.02 0.2" mass="2"/>
    <body name="left_foot" pos="0.03 0 -0.24">
      <geom type="box" size="0.1 0.05 0.01" mass="1"/>
    </body>
  </body>
  <body name="right_leg" pos="0 -0.1 -0.25"><joint name="right_hip" axis="0 1 0"/>
    <geom type="box" size="0.02 0.02 0.2" mass="2"/>
    <body name="right_foot" pos="0.03 0 -0.24">
      <geom type="box" size="0.1 0.05 0.01" mass="1"/>
    </body>
  </body>
</body></worldbody></mujoco>"""


@pytest.fixture
def box_robot(tmp_path):
    path = tmp_path / "box_robot.xml"
    path.write_text(BOX_ROBOT)
    return describe_model(str(path))


def test_the_bound_of_a_box_robot_by_hand(box_robot):
    mass = 20.0 + 2 * 2.0 + 2 * 1.0  # 26 kg
    com_x = 2 * 1.0 * 0.03 / mass  # the feet's 3 cm
    com_z = (20.0 * 0.5 + 2 * 2.0 * 0.25 + 2 * 1.0 * 0.01) / mass
    omega = math.sqrt(9.81 / com_z)
    # The support polygon: x from -7 to 13 cm, y from -15 to 15 cm.
    for direction, distance in (
        ((1.0, 0.0, 0.0), 0.13 - com_x),  # from behind: to the toes
        ((-1.0, 0.0, 0.0), 0.07 + com_x),  # from the front: to the heels
        ((0.0, 1.0, 0.0), 0.15),  # from the side: to the outer edge of the other foot
        ((1.0, 1.0, 0.0), math.sqrt(2.0) * (0.13 - com_x)),  # diagonal: the toe edge first
        ((0.0, -2.0, 5.0), 0.15),  # the vertical part does not count
    ):
        bound = no_step_bound(box_robot, direction)
        assert bound.mass_kg == pytest.approx(mass)
        assert bound.com_height_m == pytest.approx(com_z)
        assert bound.omega_per_s == pytest.approx(omega)
        assert bound.distance_m == pytest.approx(distance)
        assert bound.impulse_N_s == pytest.approx(mass * omega * distance)


def test_a_push_straight_down_has_no_bound(box_robot):
    with pytest.raises(RobotTermsError, match="no horizontal part"):
        no_step_bound(box_robot, (0.0, 0.0, -1.0))


def test_the_thesis_humanoid_bound_against_the_mid_foot_figure():
    """Issue 39's 26.5 N·s is m ω × half the sole's length (12.6 cm), from mid-foot. The
    thesis humanoid's CM stands 6.1 cm behind mid-foot (over the ankles), so the bound is
    larger from behind and smaller from the front; their mean is the mid-foot figure."""
    description = describe_model("thesis_humanoid")
    behind = no_step_bound(description, (1.0, 0.0, 0.0))
    front = no_step_bound(description, (-1.0, 0.0, 0.0))
    assert behind.distance_m + front.distance_m == pytest.approx(0.252)
    mid_foot = 0.5 * (behind.impulse_N_s + front.impulse_N_s)
    assert mid_foot == pytest.approx(26.5, abs=0.1)
    assert behind.impulse_N_s == pytest.approx(39.4, abs=0.1)
    assert front.impulse_N_s == pytest.approx(13.6, abs=0.1)


class FakeRun:
    """A stand-in run: the robot falls once the push exceeds 265 N (a push's 0.1 s: 26.5 N·s)."""

    bodies: ClassVar[list[str]] = []
    controllers: ClassVar[list[str]] = []

    def __init__(self, scenario, endpoint, curve=None):
        (push,) = scenario.pushes
        FakeRun.bodies.append(push.body)
        FakeRun.controllers.append(scenario.controller)
        self.fell = math.hypot(*push.force_in_world_N) > 265.0
        self.stopped = self.fall_reason = ""


@pytest.fixture
def fake_runs(monkeypatch):
    monkeypatch.setattr(sweep_module, "run_scenario", FakeRun)
    FakeRun.bodies, FakeRun.controllers = [], []
    return FakeRun


def sweep_args(tmp_path: Path, *extra: str) -> list[str]:
    return [
        *("sim", "stand", "--model", VENDOR, "--sweep-push", "--push-direction", "1", "0", "0"),
        *("--workers", "1", "--connect", "tcp://127.0.0.1:9", "--output", str(tmp_path)),
        *extra,
    ]


def test_the_sweep_prints_the_bound_and_sweeps_only_the_controller_given(
    fake_runs, tmp_path, capsys
):
    assert main(sweep_args(tmp_path, "--controller", "prioritized")) == 0
    printed = capsys.readouterr().out
    assert set(fake_runs.controllers) == {"prioritized"}  # not the momentum ablations
    assert set(fake_runs.bodies) == {"torso"}  # `chest` on a robot without one: its trunk
    report = json.loads((tmp_path / "sweep_stand.json").read_text())
    (label,) = report["largest_survived_N"]
    assert label == "prioritized (de Lasa 2010)" and "tracking only" not in printed
    (direction,) = report["directions"]
    bound = no_step_bound(describe_model(VENDOR), (1.0, 0.0, 0.0))
    assert report["no_step_bound"][direction]["impulse_N_s"] == pytest.approx(bound.impulse_N_s)
    survived = report["largest_survived_N"][label][direction]
    assert 260.0 <= survived <= 265.0
    impulse = report["impulse_survived_N_s"][label][direction]
    assert impulse == pytest.approx(0.1 * survived)
    share = report["fraction_of_bound"][label][direction]
    assert share == pytest.approx(impulse / bound.impulse_N_s)
    assert report["push"]["body"] == "torso"
    # Printed beside the result: the bound (N·s) and the share of it.
    assert f"{bound.impulse_N_s:.1f} N·s" in printed
    assert f"{survived:.1f} {share:4.0%}" in printed


def test_momentum_alone_is_the_full_controller(fake_runs, tmp_path, capsys):
    assert main(sweep_args(tmp_path, "--controller", "momentum")) == 0
    report = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert list(report["largest_survived_N"]) == ["+ linear and angular momentum"]
    assert set(fake_runs.controllers) == {"momentum"}


def test_a_push_body_the_robot_lacks_is_one_line_before_any_trial(fake_runs, tmp_path, capsys):
    assert main(sweep_args(tmp_path, "--push-body", "chst")) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--push-body" in line and "has no body 'chst'" in line and "torso" in line
    assert fake_runs.bodies == []
