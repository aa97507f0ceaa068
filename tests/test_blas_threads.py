"""Linear algebra runs on one thread in the tests and in `poise`, without anybody setting it."""

import json
import os
import subprocess
import sys

import threadpoolctl

from controller_server.blas import BLAS_THREAD_VARIABLES


def blas_threads() -> dict[str, int]:
    return {pool["internal_api"]: pool["num_threads"] for pool in threadpoolctl.threadpool_info()}


def test_the_test_process_runs_blas_on_one_thread():
    import numpy  # noqa: F401  (loaded long before; its BLAS read the environment then)

    threads = blas_threads()
    assert threads, "no BLAS found to check"
    assert set(threads.values()) == {1}, threads


def run_without_blas_variables(script: str, timeout_s: float, **variables: str) -> str:
    """Stdout of ``python -c script`` with none of the BLAS variables set but ``variables``."""
    environment = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    return subprocess.run(
        [sys.executable, "-c", script],
        env={**environment, **variables},
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=True,
    ).stdout


def test_poise_runs_blas_on_one_thread_when_nobody_set_it():
    # `poise list joints` loads the model with Pinocchio, so numpy's BLAS starts inside main().
    script = (
        "import json, sys, threadpoolctl\n"
        "from controller_server.cli import main\n"
        "code = main(['list', 'joints', 'thesis_humanoid'])\n"
        "assert 'numpy' in sys.modules\n"
        "pools = {p['internal_api']: p['num_threads'] for p in threadpoolctl.threadpool_info()}\n"
        "print(json.dumps({'code': code, 'pools': pools}))\n"
    )
    output = run_without_blas_variables(script, timeout_s=120)
    result = json.loads(output.splitlines()[-1])
    assert result["code"] == 0
    assert result["pools"] and set(result["pools"].values()) == {1}, result


def test_a_thread_count_the_user_set_is_kept():
    script = (
        "import os\n"
        "from controller_server.cli import main\n"
        "main(['list', 'models'])\n"
        "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])\n"
    )
    output = run_without_blas_variables(script, timeout_s=60, OPENBLAS_NUM_THREADS="2")
    assert output.splitlines()[-1] == "2 1"
