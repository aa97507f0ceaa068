"""Videos of runs and logs through the real command line (issue 20, part 1).

``poise sim … --video`` starts a real server process, runs a short pushed
scenario in the reference simulator and renders it with MuJoCo offscreen;
``poise log video`` renders a committed log. The MP4s are opened with PyAV
(the encoder's own library) and checked frame by frame: the count, motion,
and the push arrow's red present exactly while the push acts.

Frames of the committed log are also rendered unencoded, in a child process
(MuJoCo picks its OpenGL back end when first imported, and this process may
have imported it without one), to check what issue 40 asked of them: COP and
CMP markers large and in their colours where they lie, a floor that contrasts
with the robot, and the pixel projection they are placed by against MuJoCo's
own rendering.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clients.visual.video import VIDEO_FPS
from tests.helpers import moved, red_pixels, run_poise, video_frames, yellow_pixels

pytestmark = pytest.mark.e2e

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
PUSH_START_S, PUSH_DURATION_S, DURATION_S = 0.4, 0.2, 1.0
SCENARIO = f"""
name = "video_push"
description = "A chest push from behind, drawn."
duration_s = {DURATION_S}
diagnostics_period_ticks = 10

[[pushes]]
body = "chest"
force_in_world_N = [150.0, 0.0, 0.0]
start_s = {PUSH_START_S}
duration_s = {PUSH_DURATION_S}
"""


def poise(arguments: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return run_poise(arguments, cwd, timeout_s=300)


@pytest.mark.slow
def test_sim_video_shows_the_robot_moving_and_the_push_while_it_acts(tmp_path):
    scenario = tmp_path / "video_push.toml"
    scenario.write_text(SCENARIO)
    result = poise(["sim", str(scenario), "--video", "--output", "out"], tmp_path)
    assert result.returncode == 0, result.stderr

    video = video_frames(tmp_path / "out" / "video_push.mp4")
    assert abs(len(video) - DURATION_S * VIDEO_FPS) <= 1
    times = np.arange(len(video)) / VIDEO_FPS
    pushed = (times >= PUSH_START_S) & (times < PUSH_START_S + PUSH_DURATION_S)
    red = np.array([red_pixels(frame) for frame in video])
    assert red[pushed].min() > 30, red
    assert red[times < PUSH_START_S].max() == 0, red
    # The push sways the robot; the camera follows the base, so the floor grid moves too.
    assert moved(video[0], video[-1]) > 500
    assert "video_push.mp4" in (tmp_path / "out" / "report.json").read_text()


def test_log_video_draws_the_recorded_run(tmp_path):
    output = tmp_path / "push.mp4"
    log = FIXTURES / "replay_momentum_push.mcap"
    result = poise(["log", "video", str(log), "-o", str(output)], tmp_path)
    assert result.returncode == 0, result.stderr
    assert str(output) in result.stdout

    video = video_frames(output)
    assert abs(len(video) - 0.2 * VIDEO_FPS) <= 1  # the log holds 0.2 s of states
    assert moved(video[0], video[-1]) > 100  # its chest push sways the robot
    assert min(yellow_pixels(frame) for frame in video) > 20  # the support polygon
    assert max(red_pixels(frame) for frame in video) == 0  # pushes are not logged


def test_a_video_of_a_sweep_is_refused_in_one_line(tmp_path):
    result = poise(["sim", "stand", "--sweep-push", "--video"], tmp_path)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "poise sim: --video shows scenario runs; a --sweep-push has none to show"
    ]


def test_a_video_of_a_file_that_is_no_log_is_one_line(tmp_path):
    (tmp_path / "notes.mcap").write_text("not a log")
    result = poise(["log", "video", "notes.mcap"], tmp_path)
    assert result.returncode == 2
    (line,) = result.stderr.splitlines()
    assert "'notes.mcap' is not a readable Poise log" in line


RENDER_FRAMES = """
import json, sys
import numpy as np
from clients.visual.gl import choose_headless_gl
choose_headless_gl()
import mujoco
from clients.visual.overlays import overlays_at
from clients.visual.track import track_of_log
from clients.visual.video import FrameRenderer, project_to_pixels

log, out, *ticks = sys.argv[1:]
track = track_of_log(log)
frames, found = [], []
with FrameRenderer(track) as renderer:
    for tick in map(int, ticks):
        frames.append(renderer.frame(tick))
        overlays = overlays_at(track, tick, renderer.scene.point_in_world)
        scene = renderer._renderer.scene
        points = [overlays.center_of_pressure, overlays.centroidal_moment_pivot]
        points.append(np.asarray(track.states[tick].position_base_in_world))
        pixels, _ = project_to_pixels(scene, np.array(points), *frames[-1].shape[1::-1])
        found.append(pixels.tolist())
# The projection against MuJoCo's own drawing: a red ball somewhere in view of a free camera.
model = mujoco.MjModel.from_xml_string(
    '<mujoco><worldbody><geom type="sphere" size="0.05" pos="0.4 -0.3 0.6" rgba="1 0 0 1"/>'
    '</worldbody></mujoco>'
)
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
camera = mujoco.MjvCamera()
camera.lookat[:], camera.distance, camera.azimuth, camera.elevation = (0, 0, 0.5), 2.0, 120, -25
ball = mujoco.Renderer(model, 480, 640)
ball.update_scene(data, camera)
ball_pixels, _ = project_to_pixels(ball.scene, np.array([[0.4, -0.3, 0.6]]), 640, 480)
np.savez(out, frames=np.array(frames), ball_image=ball.render())
print(json.dumps({"markers": found, "ball": ball_pixels[0].tolist()}))
"""
MARKER_TICKS = (0, 100, 199)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Frames of the committed log (``MARKER_TICKS``), where their COP, CMP and base project,
    and a ball MuJoCo drew with where the projection puts it."""
    out = tmp_path_factory.mktemp("frames") / "frames.npz"
    log = FIXTURES / "replay_momentum_push.mcap"
    result = subprocess.run(
        [sys.executable, "-c", RENDER_FRAMES, str(log), str(out), *map(str, MARKER_TICKS)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert result.returncode == 0, result.stderr
    arrays = np.load(out)
    return arrays["frames"], arrays["ball_image"], json.loads(result.stdout.splitlines()[-1])


def colour_mask(image: np.ndarray, rgba: tuple[float, ...], tolerance: int = 60) -> np.ndarray:
    """Pixels within ``tolerance`` (per channel) of a marker colour."""
    target = np.round(255 * np.asarray(rgba[:3])).astype(int)
    return np.abs(image.astype(int) - target).max(axis=2) <= tolerance


def test_cop_and_cmp_markers_are_large_in_their_colours_where_they_lie(rendered):
    from clients.visual.video import CMP_RGBA, COP_RGBA

    frames, _, found = rendered
    for frame, (cop, cmp, _) in zip(frames, found["markers"], strict=True):
        disc, ring = colour_mask(frame, COP_RGBA), colour_mask(frame, CMP_RGBA)
        assert disc.sum() >= 150 and ring.sum() >= 150, (disc.sum(), ring.sum())  # ~15 px across
        rows, columns = np.nonzero(disc)
        assert abs(columns.mean() - cop[0]) < 2 and abs(rows.mean() - cop[1]) < 2  # centred
        # The CMP's ring (partly under the COP's disc when they nearly coincide) around it.
        rows, columns = np.nonzero(ring)
        distance_px = np.hypot(columns - cmp[0], rows - cmp[1])
        assert distance_px.min() > 0.4 * distance_px.max(), (distance_px.min(), distance_px.max())


def test_the_floor_contrasts_with_the_grey_robot(rendered):
    frames, _, found = rendered
    for frame, (_, _, base) in zip(frames, found["markers"], strict=True):
        column, row = np.round(base).astype(int)
        robot = frame[row - 2 : row + 3, column - 2 : column + 3].reshape(-1, 3).mean(axis=0)
        floor = frame[-40:, :40].reshape(-1, 3).mean(axis=0)  # near the camera, below the robot
        assert np.abs(robot - floor).max() > 60, (robot, floor)
        assert floor.max() - floor.min() > 30, floor  # a colour, not another grey


def test_the_marker_projection_matches_mujocos_rendering(rendered):
    _, ball_image, found = rendered
    red = (ball_image[..., 0] > 100) & (ball_image[..., 1] < 60) & (ball_image[..., 2] < 60)
    rows, columns = np.nonzero(red)
    assert red.sum() > 50
    assert columns.mean() == pytest.approx(found["ball"][0], abs=1.5)
    assert rows.mean() == pytest.approx(found["ball"][1], abs=1.5)
