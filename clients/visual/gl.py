"""Headless OpenGL for MuJoCo's offscreen renderer: EGL, else OSMesa, chosen before MuJoCo loads.

MuJoCo picks its OpenGL back end from ``MUJOCO_GL`` once, when ``mujoco`` is
first imported. :func:`choose_headless_gl` sets it, if the user has not,
before that import: ``egl`` (Mesa renders on the CPU without a display), or
``osmesa`` where EGL cannot make a context (Debian's ``libosmesa6``). Each
candidate is tried in a child process, since a back end that fails leaves
the process unable to try another. :func:`open_renderer` turns a renderer
that still cannot start into a one-line :class:`RenderingUnavailable`.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from typing import TYPE_CHECKING

from protocol.errors import PoiseError

if TYPE_CHECKING:
    import mujoco

__all__ = ["HEADLESS_BACKENDS", "RenderingUnavailable", "choose_headless_gl", "open_renderer"]

HEADLESS_BACKENDS = ("egl", "osmesa")
"""MuJoCo's headless OpenGL back ends, in the order tried."""
PROBE = (
    "import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco/>'); "
    "mujoco.Renderer(m, 8, 8).close()"
)
INSTALL_HINT = (
    "install Mesa's EGL (`apt-get install libegl1 libgl1-mesa-dri`) or OSMesa "
    "(`apt-get install libosmesa6`), or set MUJOCO_GL to a back end that works here"
)


# PyOpenGL says at INFO, on every run, that an optional speed-up is not installed.
logging.getLogger("OpenGL.acceleratesupport").setLevel(logging.WARNING)


class RenderingUnavailable(PoiseError, RuntimeError):
    """MuJoCo cannot render offscreen here; the message says what to install or set."""


def choose_headless_gl() -> str:
    """Set ``MUJOCO_GL`` to a headless back end that works, unless set; return it.

    Call before anything imports ``mujoco``; a ``MUJOCO_GL`` the user set is kept
    as is (and :func:`open_renderer` reports if it fails).

    Raises:
        RenderingUnavailable: Neither EGL nor OSMesa can make a context.
    """
    chosen = os.environ.get("MUJOCO_GL")
    if chosen:
        return chosen
    if "mujoco" in sys.modules:
        raise RenderingUnavailable(
            "MuJoCo was imported before MUJOCO_GL was set, so it cannot render offscreen: "
            "set MUJOCO_GL=egl in the environment"
        )
    for backend in HEADLESS_BACKENDS:
        probe = subprocess.run(
            [sys.executable, "-c", PROBE],
            env={**os.environ, "MUJOCO_GL": backend},
            capture_output=True,
            timeout=60,
            check=False,
        )
        if probe.returncode == 0:
            os.environ["MUJOCO_GL"] = backend
            return backend
    raise RenderingUnavailable(
        f"MuJoCo can render offscreen with neither EGL nor OSMesa: {INSTALL_HINT}"
    )


def open_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """MuJoCo's offscreen renderer of ``height`` × ``width`` pixels for ``model``.

    Raises:
        RenderingUnavailable: No OpenGL context could be made (what to install or set).
    """
    import mujoco

    try:
        return mujoco.Renderer(model, height, width)
    except ValueError:
        raise  # a frame larger than the model's offscreen buffer: a bug, not the machine
    except Exception as exc:
        detail = " ".join(str(exc).split())[:200]
        raise RenderingUnavailable(
            f"MuJoCo cannot render offscreen with MUJOCO_GL="
            f"{os.environ.get('MUJOCO_GL', '(unset)')!r} ({detail}): {INSTALL_HINT}"
        ) from None
