"""The live 3-D view in a real headless Chromium (issue 20, part 2).

``poise sim … --view`` runs a pushed scenario against a real server process
and serves the view; Chromium (Debian's ``chromium``, driven over the
DevTools protocol) loads the page while the run goes on, and two screenshots
taken apart show the robot drawn in its colour and moving. Without Chromium
the test is skipped, saying how to install it.
"""

import base64
import io
import json
import select
import shutil
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.helpers import POISE

pytestmark = pytest.mark.e2e

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1000,700",
    "--remote-debugging-port=0",
]
"""Without the background-networking flags Chromium stalls on a closed network."""
SCENE_COLUMNS = slice(0, 600)
"""The 3-D scene's part of a 1000-pixel-wide screenshot (the panel of plots is on the right)."""
WAIT_S = 90.0
"""Bound on every wait: the server, the first run's start, the page's first drawing."""
PUSHES = "\n".join(
    f'[[pushes]]\nbody = "chest"\nforce_in_world_N = [{sign * 150.0}, 0.0, 0.0]\n'
    f"start_s = {0.5 + k}\nduration_s = 0.1\n"
    for k, sign in enumerate([1, -1] * 15)
)
SCENARIO = f'name = "view_push"\nduration_s = 30.0\ndiagnostics_period_ticks = 10\n{PUSHES}'


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def robot_pixels(image: np.ndarray) -> int:
    """Pixels of the robot's blue (`clients.visual.live.ROBOT_RGB`, shaded) in the scene."""
    r, g, b = (image[:, SCENE_COLUMNS, channel].astype(int) for channel in range(3))
    return int(np.count_nonzero((b > r + 50) & (b > g + 30) & (b > 80)))


class DevTools:
    """A headless Chromium showing ``url``, driven over the DevTools protocol (CDP)."""

    def __init__(self, profile: Path, url: str):
        self.process = subprocess.Popen(
            [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", url],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            self.socket = self._connect(profile, url)
        except BaseException:
            self.process.terminate()  # a Chromium that did not open the page is not left running
            self.process.wait(timeout=30)
            raise
        self.next_id = 0

    def _connect(self, profile: Path, url: str):
        from websockets.sync.client import connect

        active_port = profile / "DevToolsActivePort"
        deadline = time.monotonic() + WAIT_S
        while not (active_port.exists() and active_port.read_text().count("\n") >= 1):
            assert time.monotonic() < deadline, "Chromium did not open its DevTools port"
            time.sleep(0.1)
        port = active_port.read_text().split()[0]
        pages: list = []
        while not pages:
            assert time.monotonic() < deadline, "Chromium did not open the page"
            time.sleep(0.1)
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as reply:
                targets = json.load(reply)
            pages = [t for t in targets if t["type"] == "page" and t["url"].startswith(url)]
        return connect(pages[0]["webSocketDebuggerUrl"], max_size=None)

    def call(self, method: str, **params):
        self.next_id += 1
        self.socket.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.socket.recv(timeout=WAIT_S))
            if reply.get("id") == self.next_id:
                assert "error" not in reply, reply
                return reply["result"]

    def screenshot(self) -> np.ndarray:
        data = self.call("Page.captureScreenshot", format="png")["data"]
        return np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB"))

    def close(self) -> None:
        self.socket.close()
        self.process.terminate()
        self.process.wait(timeout=30)


def read_line_with(process: subprocess.Popen, prefix: str) -> str:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        ready, _, _ = select.select([process.stdout], [], [], 1.0)
        if ready:
            line = process.stdout.readline()
            if line.startswith(prefix):
                return line[len(prefix) :].strip()
            assert line or process.poll() is None, process.stderr.read()
    raise AssertionError(f"`poise sim --view` printed no {prefix!r} line")


@pytest.mark.skipif(
    CHROMIUM is None,
    reason="the live view's browser test needs Chromium: `apt-get install chromium` (Debian)",
)
def test_the_page_shows_the_robot_moving_while_a_run_goes_on(tmp_path):
    (tmp_path / "view_push.toml").write_text(SCENARIO)
    port = free_port()
    sim = subprocess.Popen(
        [*POISE, "sim", "view_push.toml", "--view", "--view-port", str(port), "--output", "out"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    browser = None
    try:
        url = read_line_with(sim, "live view: ")
        assert url == f"http://127.0.0.1:{port}"
        browser = DevTools(tmp_path / "chromium-profile", url)
        deadline = time.monotonic() + WAIT_S
        first = browser.screenshot()
        while robot_pixels(first) < 1000:
            assert time.monotonic() < deadline, "the page never drew the robot"
            time.sleep(0.5)
            first = browser.screenshot()
        later = first
        while np.count_nonzero(np.abs(later.astype(int) - first.astype(int)).max(axis=2) > 40) < 50:
            assert time.monotonic() < deadline, "the robot did not move on the page"
            time.sleep(0.5)
            later = browser.screenshot()
        assert robot_pixels(later) >= 1000
        assert sim.poll() is None, "the run ended before the screenshots: make it longer"
        Image.fromarray(first).save(tmp_path / "first.png")
        Image.fromarray(later).save(tmp_path / "later.png")
    finally:
        if browser is not None:
            browser.close()
        sim.terminate()
        sim.wait(timeout=60)
