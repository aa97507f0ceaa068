"""Sweeps and scenario batteries on a pool: the same trials and results on 1 worker, 2 local
worker processes and an in-process Dask cluster; one-line errors for a bad pool.

The sweep is small on purpose: a 0.1 s push at 0.1 s, trials 0.6 s long, bisected from
800 N to 100 N (4 trials per pair), from the front, for two controllers.
"""

import json
from pathlib import Path

import pytest

from clients.physics.backend import PushSpec
from clients.pool import RunPool
from clients.sim.app import run_scenarios
from clients.sim.sweep import SWEEP_CONTROLLERS, sweep_controllers
from controller_server.cli import main

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

PUSH = PushSpec(body="chest", force_in_world_N=(1.0, 0.0, 0.0), start_s=0.1, duration_s=0.1)
CONTROLLERS = {
    label: SWEEP_CONTROLLERS[label] for label in ("tracking only", "prioritized (de Lasa 2010)")
}


def small_sweep(pool, output_dir=None):
    sweep = sweep_controllers(
        "stand",
        PUSH,
        {"from the front": (-1.0, 0.0, 0.0)},
        pool,
        {"duration_s": 0.5},
        output_dir=output_dir,
        controllers=CONTROLLERS,
        max_force_N=800.0,
        tolerance_N=100.0,
        settle_s=0.4,
        progress=False,
    )
    return {
        label: {name: b.trials for name, b in row.items()}
        for label, row in sweep.bisections.items()
    }


@pytest.fixture(scope="module")
def serial(server):
    """The small sweep in this process, one trial after the other."""
    with RunPool(endpoint=server.endpoint) as pool:
        return small_sweep(pool)


def test_the_serial_sweep_bisects_to_the_tolerance(serial):
    for row in serial.values():
        (trials,) = row.values()
        assert [force for force, _ in trials[:2]] == [800.0, 400.0]
        assert len(trials) == 4  # 800 N, then halving a 800 N interval to 100 N
        assert any(ok for _, ok in trials) and not all(ok for _, ok in trials)


def test_two_local_workers_try_the_same_forces_with_the_same_outcomes(serial, tmp_path, capsys):
    with RunPool(workers=2) as pool:  # its own server, two session workers
        assert pool.capacity == 2 and not pool.in_process
        assert small_sweep(pool, output_dir=tmp_path) == serial
    printed = capsys.readouterr().out
    assert "tracking only" in printed and f"picture: {tmp_path / 'sweep_stand.png'}" in printed
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["trials"]["tracking only"]["from the front"] == [
        {"force_N": force, "survived": ok}
        for force, ok in serial["tracking only"]["from the front"]
    ]
    assert (tmp_path / "sweep_stand.png").read_bytes().startswith(b"\x89PNG")


def test_an_in_process_dask_cluster_gives_the_serial_results(serial):
    """Two Dask workers in this process (threads), each with its own loopback server."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        with RunPool(dask=cluster.scheduler_address) as pool:
            assert pool.capacity == 2
            assert small_sweep(pool) == serial


def test_a_battery_on_two_workers_reports_in_order_what_one_worker_reports(server, tmp_path):
    names = ["stand", "head_push"]
    overrides = {"duration_s": 0.3}
    one = run_scenarios(names, tmp_path / "one", server.endpoint, overrides, progress=False)
    two = run_scenarios(
        names, tmp_path / "two", server.endpoint, overrides, progress=False, workers=2
    )
    timing = {"real_time_factor", "server_compute_p50_ms", "plot"}  # wall-clock, or paths

    def deterministic(reports):
        return [{k: v for k, v in r.items() if k not in timing} for r in reports]

    assert [r["scenario"] for r in two] == names
    assert deterministic(two) == deterministic(one)
    assert json.loads((tmp_path / "two" / "report.json").read_text()) == two
    assert (tmp_path / "two" / "head_push.png").is_file()


def test_a_trial_ended_by_a_missed_deadline_runs_again(monkeypatch, caplog):
    """DEADLINE_EXCEEDED says the machine was busy, not that the robot fell."""
    import clients.sim.sweep as sweep_module
    from clients.client import ServerTimeout

    outcomes = []

    class Run:
        def __init__(self, scenario, endpoint, curve=None):
            self.stopped = ""
            self.fell, self.fall_reason = outcomes.pop(0)

    missed = (True, f"{sweep_module.DEADLINE_MISSED}: not served within the server's deadline")
    monkeypatch.setattr(sweep_module, "run_scenario", Run)
    scenario = sweep_module.trial_scenario(
        sweep_module.load_scenario("stand"), PUSH, 100.0, settle_s=0.5
    )
    outcomes[:] = [missed, (False, "")]
    assert sweep_module.push_survived(scenario, endpoint="tcp://unused")
    assert "attempt 1 of 3" in caplog.text and not outcomes
    outcomes[:] = [missed, (True, "base tilted past 60°")]
    assert not sweep_module.push_survived(scenario, endpoint="tcp://unused")
    outcomes[:] = [missed] * sweep_module.TRIAL_ATTEMPTS
    with pytest.raises(ServerTimeout, match="missed its deadline in 3 attempts"):
        sweep_module.push_survived(scenario, endpoint="tcp://unused")


def test_the_sweep_gives_the_prioritized_controller_time_for_its_second_tries():
    """Its 20 ms QP budget would make a trial near the boundary depend on the load."""
    from clients.sim.sweep import TRIAL_QP_TIME_BUDGET_S, sweep_bases

    bases = sweep_bases("stand", controllers=CONTROLLERS)
    assert bases["prioritized (de Lasa 2010)"].params["qp_time_budget_s"] == TRIAL_QP_TIME_BUDGET_S
    assert "qp_time_budget_s" not in bases["tracking only"].params


def test_a_dask_scheduler_that_does_not_answer_is_one_line(monkeypatch, capsys, tmp_path):
    pytest.importorskip("distributed")
    import clients.pool

    monkeypatch.setattr(clients.pool, "DASK_CONNECT_TIMEOUT_S", 1.0)
    argv = ["sim", "stand", "--sweep-push", "--output", str(tmp_path)]
    assert main([*argv, "--dask", "tcp://127.0.0.1:9"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("poise sim: --dask tcp://127.0.0.1:9: no Dask scheduler answered")
    assert error.count("\n") == 1 and "Traceback" not in error


def test_workers_must_be_positive(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["sim", "stand", "--workers", "0"])
    assert exit_info.value.code == 2
    assert "argument --workers: 0 is not a whole number above zero" in capsys.readouterr().err


def start_battery(server, tmp_path):
    """`poise sim` of a 0.1 s and a 60 s stand on 2 workers, once the short one is reported."""
    import subprocess
    import sys
    import time

    scenario = tmp_path / "long_stand.toml"
    scenario.write_text('name = "long_stand"\nmodel = "thesis_humanoid"\nduration_s = 60.0\n')
    short = tmp_path / "short_stand.toml"
    short.write_text('name = "short_stand"\nmodel = "thesis_humanoid"\nduration_s = 0.1\n')
    output = tmp_path / "out"
    options = ["--workers", "2", "--connect", server.endpoint, "--output", str(output)]
    child = subprocess.Popen(
        [sys.executable, "-m", "controller_server.cli", "sim", str(short), str(scenario), *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (output / "report.json").exists():
        time.sleep(0.2)  # the short scenario is done: the long one runs
    return child, output, descendants(child.pid)


def assert_gone(pids):
    import time

    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(alive(pid) for pid in pids):
        time.sleep(0.1)
    assert not [pid for pid in pids if alive(pid)]


def test_sigterm_stops_a_battery_on_workers_and_its_worker_processes(server, tmp_path):
    """The parent stops at once (exit 130, one line), its worker processes with it."""
    import signal

    child, output, workers = start_battery(server, tmp_path)
    try:
        assert workers, "no worker processes"
        child.send_signal(signal.SIGTERM)
        stdout, stderr = child.communicate(timeout=60)
    finally:
        child.kill()
    assert child.returncode == 130, stderr
    assert stderr.strip() == "poise sim: interrupted"
    (report,) = json.loads((output / "report.json").read_text())
    assert report["scenario"] == "short_stand" and report["complete"]
    assert "short_stand" in stdout
    assert_gone(workers)


def test_workers_of_a_killed_run_stop_too(server, tmp_path):
    child, _, workers = start_battery(server, tmp_path)
    child.kill()
    child.communicate(timeout=60)
    assert workers and child.returncode == -9
    assert_gone(workers)


def descendants(pid):
    """The processes under ``pid`` (Linux /proc)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            found += [int(child), *descendants(int(child))]
    return found


def alive(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (FileNotFoundError, IndexError):
        return False


@pytest.mark.parametrize("option", [["--workers", "2"], ["--dask", "tcp://127.0.0.1:9"]])
def test_the_live_view_needs_the_runs_in_this_process(option, capsys, tmp_path):
    assert main(["sim", "stand", "--view", *option, "--output", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert (
        error
        == f"poise sim: --view shows the runs of this process, one at a time: drop {option[0]}"
        + (f" {option[1]}\n" if option[0] == "--workers" else "\n")
    )
