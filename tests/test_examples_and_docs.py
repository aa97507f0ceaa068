"""Docs, CLI help and examples stay true."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from controller_server.cli import build_parser
from controller_server.controllers import CONTROLLERS
from controller_server.controllers.docgen import render_controllers_doc
from protocol.docgen import render_protocol_doc
from tests.helpers import free_port

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


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
    "command", ["", "serve", "keygen", "demo", "sim", "bridge", "replay", "log", "list", "inspect"]
)
def test_cli_help_runs_and_is_in_the_cli_doc(command):
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
        assert f"`poise {command}" in (DOCS / "cli.md").read_text()


def test_scenarios_doc_documents_every_scenario_key_and_builtin_scenario():
    from clients.physics.backend import PushSpec
    from clients.sim.scenario import SCENARIO_DIR, ParamChange, Scenario

    doc = (DOCS / "scenarios.md").read_text()
    keys = doc.split("\n## Scenario files\n", 1)[1].split("\n## ", 1)[0]
    for model in (Scenario, PushSpec, ParamChange):
        for key in model.model_fields:
            assert f"`{key}`" in keys, key
    table = doc.split("\n## Built-in scenarios\n", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `(\w+)` \|", table, re.MULTILINE)
    assert sorted(rows) == sorted(path.stem for path in SCENARIO_DIR.glob("*.toml"))


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
        pytest.param("load.py", ["--seconds", "1"], marks=pytest.mark.slow),  # 13 s
        ("record.py", ["--blocks", "2", "--block-ticks", "50"]),
        ("bridge.py", ["--count", "40", "--chunks", "2"]),
        ("estimator.py", ["--ticks", "60", "--chunks", "2"]),
        ("dynamics_core.py", ["--calls", "200", "--chunks", "2"]),
        ("joint_limits_core.py", ["--calls", "200", "--chunks", "2"]),
        ("inverse_dynamics_core.py", ["--calls", "200", "--chunks", "2"]),
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


def client_snippet() -> str:
    """The Python block of the README's tour, "Serve"."""
    readme = (ROOT / "README.md").read_text()
    section = readme.split("\n### Serve\n", 1)[1].split("\n### ", 1)[0]
    return re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)


@pytest.mark.e2e
def test_readme_client_snippet_runs(server, tmp_path):
    snippet = client_snippet()
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


def test_readme_is_a_front_door():
    """At most 300 lines; the rest is in docs/, one page a concept (issue 33)."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 300
    for page in DOCS.glob("*.md"):
        assert f"](docs/{page.name})" in readme, f"docs/{page.name} is not in the README's contents"


def heading_anchors(markdown: str) -> set[str]:
    """GitHub's anchors of a page's headings (code blocks skipped)."""
    text = re.sub(r"^```.*?^```", "", markdown, flags=re.DOTALL | re.MULTILINE)
    anchors = set()
    for heading in re.findall(r"^#+ (.+)$", text, re.MULTILINE):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        anchors.add(slug)
    return anchors


@pytest.mark.parametrize(
    "page",
    ["README.md", "CONTRIBUTING.md", *sorted(f"docs/{p.name}" for p in DOCS.glob("*.md"))],
)
def test_every_relative_link_and_anchor_resolves(page):
    text = (ROOT / page).read_text()
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+://", target):
            continue
        path, _, anchor = target.partition("#")
        file = (ROOT / page).parent / path if path else ROOT / page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in heading_anchors(file.read_text()):
            broken.append(target)
    assert broken == []


# The README's shell commands (```sh blocks) that this test does not run, and why. Each
# entry must match a command the README shows, so the list cannot outlive the README.
README_COMMANDS_NOT_RUN = {
    "pip install": "set-up on a fresh machine: .ci/run runs it on a clean checkout "
    "(and tests/clients/test_demo.py runs `poise demo`)",
    "my_robot_map.toml": "needs a robot: actuators on a CAN bus and a server at --connect",
    "-m pytest": "the test suite itself",
}
README_SLOW_COMMANDS = ("poise sim", "poise bridge", "poise demo")
"""Commands that simulate seconds of a robot: 20–40 s each on a busy 2-core machine."""
EXPECTED_OUTPUT = re.compile(r"\s{2,}#\s+(.*?) …$")
"""A command's comment that ends in " …" starts with what the command prints."""


def readme_shell_blocks() -> list[tuple[str, list[str]]]:
    """(section, commands) of every ```sh or ```bash block, continuation lines joined."""
    readme = (ROOT / "README.md").read_text()
    blocks = []
    for match in re.finditer(r"^```(?:sh|bash)\n(.*?)^```", readme, re.DOTALL | re.MULTILINE):
        headings = re.findall(r"^#+ (.+)$", readme[: match.start()], re.MULTILINE)
        section = headings[-1].lower().replace(" ", "-")
        lines = match.group(1).replace("\\\n", " ").splitlines()
        blocks.append((section, [line for line in lines if line.strip()]))
    return blocks


def readme_command_params():
    params = []
    for index, (section, commands) in enumerate(readme_shell_blocks()):
        slow = any(name in command for command in commands for name in README_SLOW_COMMANDS)
        params.append(
            pytest.param(
                commands,
                id=f"{index}-{section}",
                marks=[pytest.mark.slow] if slow else [],
            )
        )
    return params


def not_run_reason(command: str) -> str | None:
    return next((why for key, why in README_COMMANDS_NOT_RUN.items() if key in command), None)


def test_every_readme_command_is_run_or_says_why_not():
    commands = [command for _, block in readme_shell_blocks() for command in block]
    for key in README_COMMANDS_NOT_RUN:
        assert any(key in command for command in commands), f"no README command has {key!r}"
    assert any(not_run_reason(command) is None for command in commands)


@pytest.mark.e2e
@pytest.mark.parametrize("commands", readme_command_params())
def test_readme_shell_commands_run(commands, tmp_path):
    """Each block of the README's commands runs as written, in a directory of its own.

    `.venv`, `examples` and `tests` are links to this checkout's (read only), so the
    commands' outputs (`out/`, `logs/`, a scenario) land in ``tmp_path``; a server the
    block starts in the background listens on a free port instead of 5555, and stops
    with the block.
    """
    run = [command for command in commands if not_run_reason(command) is None]
    if not run:
        pytest.skip("; ".join(sorted({not_run_reason(command) for command in commands})))
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))
    for name in ("examples", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    port = str(free_port())
    script = "\n".join(
        [
            "set -euo pipefail",
            "trap 'kill $(jobs -p) 2>/dev/null || true' EXIT",
            *(command.replace("127.0.0.1:5555", f"127.0.0.1:{port}") for command in run),
        ]
    )
    result = subprocess.run(
        ["bash", "-c", script],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, "COLUMNS": "200"},
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    printed = " ".join(output.split())
    for command in run:
        expected = EXPECTED_OUTPUT.search(command)
        if expected:
            assert " ".join(expected.group(1).split()) in printed, (command, output)
