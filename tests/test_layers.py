"""Layers point one way (docs/architecture.md): every import of every module, checked.

Two rules. Between the top-level packages: ``protocol`` imports neither of the others, the
server and the clients do not import each other (the composition root and the shared reading
of robot files excepted). Inside a package: its sub-packages and top-level modules ("units")
stand in an ordered list of layers, and a unit imports only units of layers below its own.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "controller_server", "clients")
COMPOSITION_ROOT = "controller_server/cli/"
"""`poise`: composes server and clients (the product card fixes the top level)."""
SHARED = "controller_server.models.description"
"""The one reading of robot files, shared by server and clients (docs/architecture.md): the
only server package a client may import (the package or any of its modules). It knows no
session and no wire, and imports no other server module."""
FORBIDDEN = {
    "protocol": {"controller_server", "clients"},
    "controller_server": {"clients"},
    "clients": {"controller_server"},
}

LAYERS: dict[str, list[tuple[str, ...]]] = {
    "controller_server": [
        ("errors", "blas", "params", "math"),  # math: spatial algebra, damped least squares
        ("files",),  # which files the server may read
        ("models",),  # robot
        ("momentum", "balance_points"),  # centroidal momentum rates, COP and CMP
        ("compiled",),  # the compiled core (C++, controller_server/core/): imported, checked
        ("dynamics",),  # one state's M, h, Jacobians, drifts
        ("constraints",),
        ("features",),  # each objective's rows over q̈
        ("solvers",),  # KKT of App. D, Algorithm 1, QPs
        ("inverse_dynamics", "estimation"),
        ("behaviors",),  # walk, jump: references for the controllers
        ("tasks",),  # objectives as objects, on one stack for both controllers
        ("controllers",),
        ("wire", "config", "memory", "asset_cache"),  # serving …
        ("session",),
        ("session_table",),
        ("worker",),
        ("routing",),  # what the broker tracks, where a new session goes
        ("broker_setup",),  # how it starts: CURVE, worker processes
        ("worker_pool", "stats_gather", "asset_requests"),  # its workers, stats, uploads
        ("server",),  # … the broker
        ("cli",),  # the composition root
    ],
    "clients": [
        ("layout", "progress", "explain", "server_process", "curve_keys"),  # the library …
        ("state", "client"),
        ("sampling", "load", "pool"),  # … where runs execute
        ("physics",),  # the simulated robot: backends, model files, IMU
        ("track",),  # a run tick by tick
        ("replay",),
        ("visual",),
        ("sim", "bridge"),
        ("demo", "log_info"),  # commands
    ],
}
"""Per package, its layers from the bottom up: a unit imports only units of layers below."""


def imported_modules(source: str, filename: str = "<source>") -> set[str]:
    """Modules a module imports, at module level or inside functions (dotted names)."""
    names = set()
    for node in ast.walk(ast.parse(source, filename=filename)):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module)
    return names


def unit_of(dotted: str) -> str:
    """``controller_server.features.setpoint`` → ``features``; a package's ``__init__``: ``""``."""
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 and parts[1] != "__init__" else ""


def layer_of(package: str, unit: str) -> int:
    return next(i for i, layer in enumerate(LAYERS[package]) if unit in layer)


def is_shared(dotted: str) -> bool:
    """Whether a module is the shared reading of robot files: the package or one of its modules."""
    return dotted == SHARED or dotted.startswith(SHARED + ".")


def upward_imports(module: str, source: str) -> list[str]:
    """The imports of ``module`` (a path under the root) that break either rule."""
    package = module.split("/")[0]
    dotted = module.removesuffix(".py").replace("/", ".")
    imported = imported_modules(source, module)
    broken = []
    forbidden = set() if module.startswith(COMPOSITION_ROOT) else FORBIDDEN[package]
    broken += sorted(
        name for name in imported if not is_shared(name) and name.split(".")[0] in forbidden
    )
    if package not in LAYERS or not unit_of(dotted):  # a package's __init__: its facade
        return broken
    own = unit_of(dotted)
    broken += sorted(
        name
        for name in imported
        if name.split(".")[0] == package
        and unit_of(name) not in ("", own)
        and layer_of(package, unit_of(name)) >= layer_of(package, own)
    )
    return broken


MODULES = sorted(
    path.relative_to(ROOT).as_posix()
    for package in PACKAGES
    for path in (ROOT / package).rglob("*.py")
)


def test_no_module_imports_a_layer_it_must_not():
    offenders = {
        module: broken
        for module in MODULES
        if (broken := upward_imports(module, (ROOT / module).read_text()))
    }
    assert not offenders, "\n".join(f"{m} imports {b}" for m, b in offenders.items())


def test_every_unit_has_a_layer():
    for package, layers in LAYERS.items():
        units = {
            path.stem if path.is_file() else path.name
            for path in (ROOT / package).iterdir()
            if (path.suffix == ".py" and path.stem != "__init__")
            or (path / "__init__.py").is_file()
        }
        placed = [unit for layer in layers for unit in layer]
        assert len(placed) == len(set(placed)), f"{package}: a unit in two layers"
        assert units == set(placed), (package, units ^ set(placed))


def test_a_planted_upward_import_is_found():
    setpoint = "controller_server/features/setpoint.py"
    source = (ROOT / setpoint).read_text()
    assert upward_imports(setpoint, source) == []
    planted = source + "\nfrom controller_server.controllers.base import ParamSpec\n"
    assert upward_imports(setpoint, planted) == ["controller_server.controllers.base"]
    # sideways: the simulator and the bridge stand side by side, neither imports the other
    plant = "clients/bridge/plant.py"
    planted = (ROOT / plant).read_text() + "\ndef f():\n    from clients.sim import runner\n"
    assert upward_imports(plant, planted) == ["clients.sim"]
    # across packages
    track = "clients/track.py"
    planted = (ROOT / track).read_text() + "\nimport controller_server.server\n"
    assert upward_imports(track, planted) == ["controller_server.server"]


def test_the_shared_reading_of_robot_files_imports_no_other_layer_module():
    paths = sorted((ROOT / SHARED.replace(".", "/")).rglob("*.py"))
    assert len(paths) > 1
    outside = {}
    for path in paths:
        project = {
            name
            for name in imported_modules(path.read_text())
            if name.split(".")[0] in PACKAGES and not is_shared(name)
        }
        # the wire's messages and its errors (which protocol.messages imports itself)
        if not project <= {"protocol.messages", "protocol.errors"}:
            outside[path.relative_to(ROOT).as_posix()] = sorted(project)
    assert not outside, outside


def test_the_check_sees_imports_inside_functions():
    runs = COMPOSITION_ROOT + "runs.py"
    assert any(name.startswith("clients.") for name in imported_modules((ROOT / runs).read_text()))
    assert len(MODULES) > 50
