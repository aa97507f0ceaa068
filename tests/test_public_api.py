"""Every subpackage's ``__all__`` names exist, so the exported surface can't rot."""

import importlib

import pytest

PACKAGES = [
    "protocol",
    "protocol.arrays",
    "protocol.codec",
    "protocol.errors",
    "protocol.messages",
    "controller_server.models",
    "controller_server.features",
    "controller_server.features.swing_twist",
    "controller_server.features.joint_limits",
    "controller_server.features.motion_clip",
    "controller_server.features.linear_momentum",
    "controller_server.features.angular_momentum",
    "controller_server.features.point_acceleration",
    "controller_server.momentum",
    "controller_server.balance_points",
    "controller_server.spatial",
    "controller_server.solvers.damped",
    "controller_server.controllers.momentum",
    "controller_server.constraints",
    "controller_server.solvers",
    "controller_server.controllers",
    "controller_server.dynamics",
    "controller_server.inverse_dynamics",
    "controller_server.server",
    "controller_server.session",
    "controller_server.session_table",
    "controller_server.worker",
    "controller_server.config",
    "controller_server.files",
    "controller_server.wire",
    "clients",
    "clients.client",
    "protocol.recording",
    "clients.replay",
    "clients.progress",
    "clients.log_info",
    "clients.sampling",
    "clients.load",
    "clients.state",
    "clients.sim.backend",
    "clients.sim.model_file",
    "clients.sim.reference",
    "clients.sim.mujoco_backend",
    "clients.sim.scenario",
    "clients.sim.runner",
    "clients.sim.metrics",
    "clients.sim.plots",
    "clients.sim.app",
    "clients.sim.errors",
]


@pytest.mark.parametrize("name", PACKAGES)
def test_all_names_exist(name):
    module = importlib.import_module(name)
    assert module.__all__
    for exported in module.__all__:
        assert hasattr(module, exported), f"{name}.{exported}"


def test_protocol_does_not_import_robotics_code():
    import subprocess
    import sys

    heavy = ("pinocchio", "controller_server", "clients")
    code = f"import sys, protocol; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    assert subprocess.check_output([sys.executable, "-c", code], text=True).strip() == "[]"


def test_the_broker_does_not_import_robotics_code():
    """The broker process routes bytes; Pinocchio and the controllers live in the workers."""
    import subprocess
    import sys

    code = (
        "import sys, controller_server.server, controller_server.cli; "
        "print(sorted(m for m in ('pinocchio', 'controller_server.controllers') "
        "if m in sys.modules))"
    )
    assert subprocess.check_output([sys.executable, "-c", code], text=True).strip() == "[]"


def test_cli_controller_choices_are_the_servers_controllers():
    from controller_server.cli import CONTROLLER_NAMES
    from controller_server.controllers import CONTROLLERS

    assert sorted(CONTROLLERS) == CONTROLLER_NAMES
