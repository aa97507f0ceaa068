"""PEP 517 backend of Poise: scikit-build-core, after checking that a C++ compiler exists.

``pyproject.toml`` names it (``build-backend = "poise_backend"``, ``backend-path``). It is
a build tool, not part of the installed packages (the wheel leaves ``controller_server/core/``
out). Without a compiler, pip then shows one line naming what to install instead of CMake's
log. The check mirrors what CMake will be given: scikit-build-core sets ``CXX`` from
Python's own build configuration (``sysconfig``, usually ``g++``) when the user has not set
it. ``controller_server/core/CMakeLists.txt`` checks again, for builds that skip this.
"""

from __future__ import annotations

import os
import shlex
import shutil
import sysconfig

from scikit_build_core.build import *  # noqa: F403  (every PEP 517 hook, unchanged)
from scikit_build_core.build import build_editable as _build_editable
from scikit_build_core.build import build_wheel as _build_wheel


def _require_compiler() -> None:
    cxx = os.environ.get("CXX") or sysconfig.get_config_var("CXX") or "c++"
    program = shlex.split(cxx)[0]
    if shutil.which(program) is None:
        raise SystemExit(
            f"No C++ compiler ({program} not found): install g++ (Debian: apt-get install g++) "
            "or set CXX"
        )


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    """PEP 517 ``build_wheel``: scikit-build-core's, once a compiler is found."""
    _require_compiler()
    return _build_wheel(wheel_directory, config_settings, metadata_directory)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    """PEP 660 ``build_editable``: scikit-build-core's, once a compiler is found."""
    _require_compiler()
    return _build_editable(wheel_directory, config_settings, metadata_directory)
