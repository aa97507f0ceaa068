"""The exported surface: every module says what it exports, exports what others use, documents it.

Modules are found on disk (a new one is checked without being listed). For
each: a docstring and an ``__all__`` whose names exist and are documented;
and every name another Poise module imports from it is in its ``__all__``
(a module's public surface is what the rest of the code relies on).
"""

import ast
import importlib
import inspect
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "controller_server", "clients")
SCRIPTS = {"controller_server.cli.__main__", "controller_server.worker"}
"""Entry points run with ``python -m``: their surface is their command line."""
BUILD_TOOLS = {"controller_server.core.build_backend.poise_backend"}
"""The build backend pyproject.toml names: it runs in pip's build environment (it imports
scikit-build-core) and is not installed; its surface is PEP 517's hooks."""


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = sorted(
    module_name(path) for package in PACKAGES for path in (ROOT / package).rglob("*.py")
)


@pytest.mark.parametrize("name", MODULES)
def test_every_module_documents_and_exports_its_surface(name):
    if name in SCRIPTS | BUILD_TOOLS:  # importing runs it, or cannot: read its docstring only
        path = ROOT / Path(*name.split(".")).with_suffix(".py")
        assert ast.get_docstring(ast.parse(path.read_text())), f"{name} has no docstring"
        return
    module = importlib.import_module(name)
    assert inspect.getdoc(module), f"{name} has no docstring"
    exported = getattr(module, "__all__", None)
    assert exported is not None, f"{name} has no __all__"
    for public in exported:
        assert hasattr(module, public), f"{name}.{public} does not exist"
        value = getattr(module, public)
        if inspect.isclass(value) or inspect.isfunction(value):
            assert inspect.getdoc(value), f"{name}.{public} has no docstring"


def imports_between_modules() -> list[tuple[str, str, str]]:
    """(importer, module, name) for every ``from poise_module import name`` in the code."""
    found = []
    for importer in MODULES:
        path = ROOT / Path(*importer.split("."))
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                if node.module.split(".")[0] in PACKAGES and node.module in MODULES:
                    found += [(importer, node.module, alias.name) for alias in node.names]
    return found


IMPORTS = imports_between_modules()


@pytest.mark.parametrize(
    ("importer", "module", "name"),
    [(i, m, n) for i, m, n in IMPORTS if not n.startswith("_") and m not in SCRIPTS],
    ids=[f"{m}.{n}<-{i}" for i, m, n in IMPORTS if not n.startswith("_") and m not in SCRIPTS],
)
def test_what_other_modules_import_is_exported(importer, module, name):
    imported = importlib.import_module(module)
    if inspect.ismodule(getattr(imported, name, None)):
        return  # a submodule, imported by name
    assert name in imported.__all__, f"{importer} imports {module}.{name}, not in its __all__"


def test_no_module_imports_a_private_name_of_another():
    private = [f"{m}.{n} <- {i}" for i, m, n in IMPORTS if n.startswith("_") and m != i]
    assert not private, private


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
