"""A user's mistake through the real command line: one line on stderr, exit code 2, a hint.

Each case runs ``python -m controller_server.cli`` (what the ``poise`` script
runs) in a subprocess, in a temporary directory, bounded by a timeout.
"""

import socket
import subprocess
from pathlib import Path

import pytest

from tests import helpers

TIMEOUT_S = 90  # the slowest case waits out the client's 10 s hello timeout


def scenario(directory: Path, text: str) -> str:
    path = directory / "mistake.toml"
    path.write_text('name = "mistake"\nduration_s = 0.05\n' + text)
    return str(path)


def scene_without_robot(directory: Path) -> Path:
    """A vendor-style scene whose ``<include>``d robot file is missing (issue 18)."""
    path = directory / "scene.xml"
    path.write_text('<mujoco><include file="robot.xml"/><worldbody/></mujoco>')
    return path


def existing_file(directory: Path) -> Path:
    path = directory / "results"
    path.write_text("not a directory")
    return path


def robot_directory(directory: Path) -> Path:
    """A vendor's robot folder, given where its file was meant."""
    folder = directory / "h1"
    folder.mkdir()
    for name in ("scene.xml", "robot.urdf", "README.md"):
        (folder / name).write_text("")
    return folder


def sim(directory: Path, *arguments: str) -> list[str]:
    """``poise sim ARGUMENTS`` writing its report (if it got that far) into ``directory``."""
    return ["sim", *arguments, "--output", str(directory / "out")]


# (id, arguments given the temporary directory, text the one line must contain)
MISTAKES = [
    (
        "nothing listening",
        lambda d: sim(d, "stand", "--connect", f"tcp://127.0.0.1:{helpers.free_port()}"),
        ["nothing answers at tcp://127.0.0.1:", "is `poise serve` running there?"],
    ),
    (
        "endpoint without scheme",
        lambda d: sim(d, "stand", "--connect", "localhost:5555"),
        ["write tcp://localhost:5555"],
    ),
    (
        "bind without scheme",
        lambda d: ["serve", "--bind", "localhost:5555"],
        ["--bind", "write tcp://localhost:5555"],
    ),
    (
        "unknown scenario",
        lambda d: sim(d, "no_such_scenario"),
        ["no scenario 'no_such_scenario'", "push_sequence", "stand"],
    ),
    (
        "typo in a scenario key",
        lambda d: sim(d, scenario(d, "duraton_s = 1.0\n")),
        ["unknown key 'duraton_s'; did you mean 'duration_s'?"],
    ),
    (
        "missing model file",
        lambda d: sim(d, scenario(d, f'model = "{d}/does_not_exist.xml"\n')),
        ["model file", "does_not_exist.xml' does not exist"],
    ),
    (
        "misspelled joint",
        lambda d: sim(d, scenario(d, "[initial_joint_position]\nlft_knee = [0, 0, 0, 1]\n")),
        ["no joint 'lft_knee'; did you mean 'left_knee'?", "right_ankle"],
    ),
    (
        "misspelled push body",
        lambda d: sim(
            d,
            scenario(
                d,
                "[[pushes]]\nbody = 'chst'\nforce_in_world_N = [10.0, 0.0, 0.0]\n"
                "start_s = 0.1\nduration_s = 0.1\n",
            ),
        ),
        ["pushes[0].body", "no body 'chst'; did you mean 'chest'?", "right_foot"],
    ),
    (
        "joint value as a number",
        lambda d: sim(d, scenario(d, "[initial_joint_position]\nleft_knee = 0.3\n")),
        ["initial_joint_position.left_knee = 0.3: give a list", "[x, y, z, w]"],
    ),
    (
        "a scene whose included robot is missing",
        lambda d: sim(d, scenario(d, f'model = "{scene_without_robot(d)}"\n')),
        ["model: <include file> names 'robot.xml', which cannot be read: No such file"],
    ),
    (
        "a keyframe the model does not have",
        lambda d: sim(d, "stand", "--keyframe", "home"),
        ["keyframe: no keyframe 'home' in the model; keyframes: none"],
    ),
    (
        "a misspelled foot",
        lambda d: sim(d, "stand", "--contacts", "left_fot", "right_foot"),
        ["contacts: no frame 'left_fot' in the model; did you mean 'left_foot'?"],
    ),
    (
        "inspect a file that is not there",
        lambda d: ["inspect", "robot.xml"],
        ["model file 'robot.xml' does not exist"],
    ),
    (
        "misspelled imu body",
        lambda d: sim(d, scenario(d, 'base_state = "imu"\n[imu]\nbody = "pelvs"\n')),
        ["imu.body", "no body 'pelvs'; did you mean 'pelvis'?"],
    ),
    (
        "imu rate other than the control rate",
        lambda d: sim(d, scenario(d, 'base_state = "imu"\n[imu]\nrate_hz = 400.0\n')),
        ["imu.rate_hz (400) must equal control_rate_hz (1000)"],
    ),
    (
        "imu with a delayed command",
        lambda d: sim(d, scenario(d, 'base_state = "imu"\ncommand_delay_ticks = 1\n')),
        ['base_state = "imu" needs command_delay_ticks = 0'],
    ),
    (
        "unknown controller parameter",
        lambda d: sim(d, scenario(d, "[params]\nstifnes = 3.0\n")),
        [
            "the server refused the request: INVALID_PARAMS",
            "stifnes",
            "did you mean 'stiffness'?",
        ],
    ),
    (
        "an option of the wrong kind",
        lambda d: sim(d, "stand", "--backend", "bullet"),
        [
            "poise sim: argument --backend: invalid choice: 'bullet'",
            "(`poise sim --help` for more)",
        ],
    ),
    (
        "an option the subcommand does not have",
        lambda d: ["log", "info", "x.mcap", "--frobnicate"],
        ["poise log info: unrecognized arguments: --frobnicate", "`poise log info --help`"],
    ),
    (
        "a negative bridge duration",
        lambda d: ["bridge", "map.toml", "--emulate", "--duration", "-5"],
        ["poise bridge: argument --duration: -5 is not a finite number zero or more"],
    ),
    (
        "a negative replay deadline",
        lambda d: ["replay", "log.mcap", "--deadline", "-1"],
        ["argument --deadline: -1 is not a finite number above zero"],
    ),
    (
        "no workers",
        lambda d: sim(d, "stand", "--workers", "0"),
        ["argument --workers: 0 is not a whole number above zero"],
    ),
    (
        "a sweep's push of negative duration",
        lambda d: sim(d, "stand", "--sweep-push", "--push-duration", "-0.1"),
        ["argument --push-duration: -0.1 is not a finite number above zero"],
    ),
    (
        "a sweep's push of no direction",
        lambda d: sim(d, "stand", "--sweep-push", "--push-direction", "0", "0", "0"),
        ["--push-direction 0 0 0: give a direction with a horizontal part"],
    ),
    (
        "a file where the output directory goes",
        lambda d: ["demo", "--output", str(existing_file(d))],
        ["poise demo: --output", "a file is in the way", "choose another --output"],
    ),
    (
        "a model path that is a directory",
        lambda d: sim(d, "stand", "--model", str(robot_directory(d))),
        ["is a directory: give the robot's .xml", "in it: robot.urdf, scene.xml"],
    ),
    (
        "joint value of the wrong length",
        lambda d: sim(d, scenario(d, "[initial_joint_position]\nleft_knee = [0.3]\n")),
        ["a ball joint takes 4 number(s)"],
    ),
]


def run_poise(arguments: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return helpers.run_poise(arguments, cwd, TIMEOUT_S)


@pytest.mark.parametrize(
    ("arguments", "hints"),
    [
        # Nothing listening is told after the client's 10 s connect timeout.
        pytest.param(
            *m[1:], id=m[0], marks=[pytest.mark.slow] if m[0] == "nothing listening" else []
        )
        for m in MISTAKES
    ],
)
def test_a_mistake_is_one_line_and_exit_code_2(arguments, hints, tmp_path):
    result = run_poise(arguments(tmp_path), tmp_path)
    lines = result.stderr.splitlines()
    assert "Traceback" not in result.stderr, result.stderr
    assert len(lines) == 1, result.stderr
    assert result.returncode == 2, result.stderr
    for hint in hints:
        assert hint in lines[0], lines[0]


def test_port_already_in_use(tmp_path):
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        result = run_poise(
            ["serve", "--workers", "1", "--bind", f"tcp://127.0.0.1:{port}"], tmp_path
        )
    assert "Traceback" not in result.stderr, result.stderr
    assert result.stderr.splitlines() == [
        f"poise serve: cannot bind 'tcp://127.0.0.1:{port}': Address already in use "
        f"(addr='tcp://127.0.0.1:{port}'); another process (another `poise serve`?) listens "
        "there: stop it, or bind another port (port * picks a free one)"
    ]
    assert result.returncode == 2


def test_debug_shows_the_traceback(tmp_path):
    result = run_poise(["--debug", "sim", "no_such_scenario"], tmp_path)
    assert "Traceback" in result.stderr
    assert "ScenarioNotFound: no scenario 'no_such_scenario'" in result.stderr
    assert result.returncode == 1
