"""Docs, CLI help and examples stay true."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

from controller_server.cli import build_parser
from controller_server.controllers import CONTROLLERS
from controller_server.controllers.docgen import render_controllers_doc
from protocol.docgen import render_protocol_doc

ROOT = Path(__file__).resolve().parents[1]


def test_protocol_doc_is_generated_from_the_models():
    committed = (ROOT / "docs" / "protocol.md").read_text()
    assert committed == render_protocol_doc(), "run: python -m protocol.docgen > docs/protocol.md"


def test_controllers_doc_is_generated_from_the_parameter_specs():
    committed = (ROOT / "docs" / "controllers.md").read_text()
    assert committed == render_controllers_doc(), (
        "run: python -m controller_server.controllers.docgen > docs/controllers.md"
    )
    for name, cls in CONTROLLERS.items():
        assert f"`{name}`" in committed
        for key in cls.PARAMETERS:
            assert f"`{key}`" in committed, key


def test_readme_commands_are_what_ci_runs():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    test_command = re.search(r"```sh\n(.*pytest.*)\n```", readme).group(1)
    assert test_command in ci
    assert "poise demo" in readme


@pytest.mark.parametrize(
    "command", ["", "serve", "keygen", "demo", "sim", "bridge", "replay", "log", "list"]
)
def test_cli_help_runs_and_is_in_the_readme(command):
    args = [
        sys.executable,
        "-m",
        "controller_server.cli",
        *([command] if command else []),
        "--help",
    ]
    output = subprocess.check_output(args, text=True, cwd=ROOT)
    assert "usage: poise" in output
    if command:
        assert f"poise {command}" in (ROOT / "README.md").read_text()


def test_readme_documents_every_scenario_key_and_builtin_scenario():
    from clients.sim.scenario import SCENARIO_DIR, ParamChange, PushSpec, Scenario

    readme = (ROOT / "README.md").read_text()
    for model in (Scenario, PushSpec, ParamChange):
        for key in model.model_fields:
            assert f"`{key}`" in readme, key
    for path in SCENARIO_DIR.glob("*.toml"):
        assert f"`{path.stem}`" in readme, path.stem


def test_bridge_doc_documents_every_key_of_the_actuator_map():
    from clients.bridge.config import (
        BridgeSettings,
        BusSpec,
        EmulationSpec,
        ImuSettings,
        JointActuator,
    )

    doc = (ROOT / "docs" / "bridge.md").read_text()
    for model in (BridgeSettings, BusSpec, JointActuator, ImuSettings, EmulationSpec):
        for key in model.model_fields:
            assert f"| `{key}` |" in doc, key


def test_parser_lists_every_subcommand():
    help_text = build_parser().format_help()
    assert "serve" in help_text and "demo" in help_text


@pytest.mark.e2e
def test_hello_client_example_runs(server):
    output = subprocess.check_output(
        [sys.executable, str(ROOT / "examples" / "hello_client.py"), server.endpoint],
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert "tick 4" in output
    forces = [float(x) for x in re.findall(r"ground force\s+([\d.]+) N", output)]
    assert all(abs(f - 65.0 * 9.81) < 1.0 for f in forces), output


@pytest.mark.e2e
@pytest.mark.parametrize(
    ("script", "args"),
    [
        ("roundtrip.py", ["--count", "50"]),
        ("controller.py", ["--ticks", "30"]),
        ("load.py", ["--seconds", "1"]),
        ("record.py", ["--blocks", "2", "--block-ticks", "50"]),
        ("bridge.py", ["--count", "40", "--chunks", "2"]),
        ("estimator.py", ["--ticks", "60", "--chunks", "2"]),
    ],
)
def test_benchmarks_run_and_print_ratios(script, args):
    output = subprocess.check_output(
        [sys.executable, str(ROOT / "bench" / script), *args], text=True, cwd=ROOT, timeout=300
    )
    assert re.search(r"\d+\.\d+x", output), output


def test_serve_defaults_are_the_config_defaults():
    """`poise serve`'s option defaults and ServeConfig's are one set of numbers."""
    import dataclasses

    from controller_server.cli.serve import serve_config
    from controller_server.config import ServeConfig

    parsed = serve_config(build_parser().parse_args(["serve"]))
    expected = ServeConfig(workers=parsed.workers, log_level=parsed.log_level)
    assert dataclasses.asdict(parsed) == dataclasses.asdict(expected)


def _options(parser, command=("poise",)):
    """(command, action) for every option of ``parser`` and its subcommands."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, subparser in action.choices.items():
                yield from _options(subparser, (*command, name))
        elif action.option_strings and action.dest != "help":
            yield " ".join(command), action


def test_every_option_says_what_it_does():
    missing = [f"{c} {a.option_strings[0]}" for c, a in _options(build_parser()) if not a.help]
    assert missing == []


def test_sim_and_demo_options_state_their_defaults():
    unstated = [
        f"{command} {action.option_strings[0]}"
        for command, action in _options(build_parser())
        if command in ("poise sim", "poise demo")
        and action.default not in (None, False)
        and f"default: {action.default}" not in action.help
    ]
    assert unstated == []


def test_demo_help_names_the_backend_choice():
    demo_help = subprocess.check_output(
        [sys.executable, "-m", "controller_server.cli", "demo", "--help"], text=True, cwd=ROOT
    )
    assert "reference simulator" not in demo_help
    assert "--backend {reference,mujoco}" in demo_help


def quick_start_snippet() -> str:
    """The Python block of the README's Quick start."""
    readme = (ROOT / "README.md").read_text()
    section = readme.split("\n## Quick start\n", 1)[1].split("\n## ", 1)[0]
    return re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)


@pytest.mark.e2e
def test_readme_quick_start_snippet_runs(server, tmp_path):
    snippet = quick_start_snippet()
    assert "tcp://127.0.0.1:5555" in snippet
    script = tmp_path / "quick_start.py"
    script.write_text(snippet.replace("tcp://127.0.0.1:5555", server.endpoint))
    output = subprocess.check_output(
        [sys.executable, str(script)], text=True, cwd=tmp_path, timeout=120
    )
    torques = [float(x) for x in re.findall(r"-?\d+\.\d*(?:e[-+]\d+)?", output)]
    assert len(torques) >= 20, output  # 39 joint torques of the thesis humanoid


@pytest.mark.e2e
def test_hello_picks_the_momentum_controller_by_default(server):
    from clients import ControllerClient
    from protocol import Hello

    assert Hello(model="thesis_humanoid").controller == "momentum"
    with ControllerClient(server.endpoint, timeout_s=10.0) as client:
        assert client.connect("thesis_humanoid").controller == "momentum"
