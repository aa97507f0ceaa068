"""Layers point one way (docs/architecture.md): every import of every module, checked."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "controller_server", "clients")
COMPOSITION_ROOT = "controller_server/cli/"
"""`poise`: composes server and clients (the product card fixes the top level)."""
SHARED = "controller_server.models.description"
"""The one reading of robot files, shared by server and clients (docs/architecture.md): the
only server module a client may import. It knows no session and no wire, and imports no
other server module."""
FORBIDDEN = {
    "protocol": {"controller_server", "clients"},
    "controller_server": {"clients"},
    "clients": {"controller_server"},
}


def imported_modules(path: Path) -> set[str]:
    """Modules a module imports, at module level or inside functions (dotted names)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module)
    return names


def imported_packages(path: Path) -> set[str]:
    """Top-level packages a module imports, the shared reading of robot files left out."""
    return {name.split(".")[0] for name in imported_modules(path) if name != SHARED}


MODULES = sorted(
    path.relative_to(ROOT).as_posix()
    for package in PACKAGES
    for path in (ROOT / package).rglob("*.py")
)


@pytest.mark.parametrize("module", MODULES)
def test_no_module_imports_a_layer_it_must_not(module):
    package = module.split("/")[0]
    forbidden = set() if module.startswith(COMPOSITION_ROOT) else FORBIDDEN[package]
    assert not imported_packages(ROOT / module) & forbidden, (
        f"{module} imports {sorted(imported_packages(ROOT / module) & forbidden)}"
    )


def test_the_shared_reading_of_robot_files_imports_no_other_layer_module():
    path = ROOT / (SHARED.replace(".", "/") + ".py")
    project = {name for name in imported_modules(path) if name.split(".")[0] in PACKAGES}
    # the wire's messages and its errors (which protocol.messages imports itself)
    assert project <= {"protocol.messages", "protocol.errors"}, project


def test_the_check_sees_imports_inside_functions():
    assert "clients" in imported_packages(ROOT / COMPOSITION_ROOT / "runs.py")
    assert len(MODULES) > 50
