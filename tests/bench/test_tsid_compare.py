"""bench/tsid_compare.py without TSID: Poise and the floor measured, TSID skipped with a reason.

TSID lives in a venv of its own (docs/benchmarks.md), so these runs exercise
the paths a machine without it takes; no wall-clock time is asserted.
"""

import os
import re
import subprocess
import sys
from importlib.util import find_spec
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "bench" / "tsid_compare.py"

pytestmark = pytest.mark.skipif(
    find_spec("tsid") is not None, reason="tsid is installed here: the script would run it"
)


def run_script(*args: str) -> subprocess.CompletedProcess[str]:
    environment = {k: v for k, v in os.environ.items() if k != "POISE_TSID_PYTHON"}
    return subprocess.run(
        [sys.executable, str(SCRIPT), "--ticks", "30", *args],
        env=environment,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_without_tsid_it_times_poise_and_the_floor_and_says_how_to_add_tsid():
    run = run_script()
    assert run.returncode == 0, run.stderr
    output = run.stdout
    assert "TSID skipped" in output and "docs/benchmarks.md" in output, output
    assert not re.search(r"^TSID:", output, re.MULTILINE), output
    assert re.search(r"^floor: .*\s\d+\s+\d+\s+1\.0x$", output, re.MULTILINE), output
    weight_N = float(re.search(r"weight (\d+) N", output).group(1))
    for kernel in ("compiled tick", "Python tick"):  # side by side
        poise = re.search(
            rf"^Poise momentum, {kernel}.*?\s+(\d+)\s+(\d+)\s+(\d+\.\d)x\s+(\d+)\s+(\d+)$",
            output,
            re.MULTILINE,
        )
        assert poise, output
        normal_force_N, failed = float(poise.group(4)), int(poise.group(5))
        # Near standing the soles carry about the weight: the states and the table are sound.
        assert abs(normal_force_N - weight_N) < 0.2 * weight_N, output
        assert failed == 0, output


def test_an_interpreter_without_tsid_stops_the_run_with_its_error():
    run = run_script("--tsid-python", sys.executable)
    assert run.returncode != 0
    assert "TSID worker" in run.stderr and "No module named 'tsid'" in run.stderr, run.stderr


def test_a_model_with_ball_joints_is_refused_by_name():
    run = run_script("--model", "thesis_humanoid")
    assert run.returncode != 0
    assert "multi-DoF joints" in run.stderr and "revolute_humanoid" in run.stderr, run.stderr
