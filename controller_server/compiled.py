"""The compiled core, ``controller_server._core``: imported once, checked, or one clear error.

The core (C++ with nanobind and Pinocchio, sources in ``controller_server/core/``) is built
by ``pip install``; docs/architecture.md#the-compiled-core. This module only finds it, so
that the broker can check it at start-up without importing the robot models, and so that
a missing or stale build is one line naming the fix, never a silent fall back to Python
(which would hide a broken install behind a 3× slower tick).

The core reads the Pinocchio model as the text of ``pin.Model.saveToString()`` and loads
the runtime's ``libpinocchio_default.so``: it must have been compiled against the
Pinocchio that Python imports (``pyproject.toml`` pins the same range for both).
"""

from __future__ import annotations

import importlib
from functools import cache
from types import ModuleType

__all__ = ["CORE_MODULE", "CompiledCoreUnavailable", "load_core"]

CORE_MODULE = "controller_server._core"
"""The extension module's import name."""

_FIX = (
    "reinstall Poise (`.venv/bin/pip install -e .`, which needs a C++ compiler: "
    "Debian `apt-get install g++`)"
)
"""The fix every :class:`CompiledCoreUnavailable` names."""


class CompiledCoreUnavailable(ImportError):
    """``controller_server._core`` cannot be imported, or was built for another Pinocchio.

    Its message is one line: what is wrong and how to fix it.
    """


@cache
def load_core() -> ModuleType:
    """The compiled core module, imported once per process.

    Raises:
        CompiledCoreUnavailable: It is missing or broken (not built, a library not found),
            or it was compiled against another Pinocchio than the one imported.
    """
    try:
        module = importlib.import_module(CORE_MODULE)
    except ImportError as error:
        detail = " ".join(str(error).split()) or type(error).__name__
        raise CompiledCoreUnavailable(
            f"the compiled core {CORE_MODULE} cannot be imported ({detail}): {_FIX}"
        ) from error
    import pinocchio

    if module.PINOCCHIO_VERSION != pinocchio.__version__:
        raise CompiledCoreUnavailable(
            f"the compiled core {CORE_MODULE} was built against Pinocchio "
            f"{module.PINOCCHIO_VERSION} but Python imports pin {pinocchio.__version__}: "
            f"{_FIX}"
        )
    return module
