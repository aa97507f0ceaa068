"""Layers point one way (docs/architecture.md): every import of every module, checked."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "controller_server", "clients")
COMPOSITION_ROOT = "controller_server/cli/"
"""`poise`: composes server and clients (the product card fixes the top level)."""
FORBIDDEN = {
    "protocol": {"controller_server", "clients"},
    "controller_server": {"clients"},
    "clients": {"controller_server"},
}


def imported_packages(path: Path) -> set[str]:
    """Top-level packages a module imports, at module level or inside functions."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module.split(".")[0])
    return names


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


def test_the_check_sees_imports_inside_functions():
    assert "clients" in imported_packages(ROOT / COMPOSITION_ROOT / "runs.py")
    assert len(MODULES) > 50
