"""A sweep keeps its work (issue 40, "Sweeps lose their work").

`sweep_<scenario>.json` and the picture are rewritten after every finished bisection and once
more when the sweep ends, however it ends; until every bisection is done the JSON says
`"complete": false`. The bookkeeping is checked through `poise sim` in this process with a
stand-in for the simulated run (fast); the acceptance, a real sweep stopped by SIGTERM, through
the command line in a subprocess (slow).
"""

import json
import math
import signal
import subprocess
import time
from pathlib import Path
from typing import ClassVar

import pytest

import clients.sim.sweep as sweep_module
from controller_server.cli import main
from tests.helpers import POISE, run_poise

FIRST_ROW = "tracking only"


class FakeRun:
    """A stand-in run: the robot falls above 265 N; run number ``interrupt_at`` stops as
    ``stop_reason`` says (Ctrl-C by default).

    Each bisection (2000 N down to 5 N) takes 10 trials. Before each run it reads what the
    sweep has written so far.
    """

    output: ClassVar[Path]
    interrupt_at: ClassVar[int | None] = None
    stop_reason: ClassVar[str] = "interrupted"
    runs: ClassVar[int] = 0
    seen: ClassVar[list[dict | None]] = []

    def __init__(self, scenario, endpoint, curve=None):
        path = FakeRun.output / "sweep_stand.json"
        FakeRun.seen.append(json.loads(path.read_text()) if path.exists() else None)
        FakeRun.runs += 1
        (push,) = scenario.pushes
        self.fell = math.hypot(*push.force_in_world_N) > 265.0
        self.fall_reason = ""
        self.stopped = FakeRun.stop_reason if FakeRun.runs == FakeRun.interrupt_at else ""


@pytest.fixture
def fake_runs(monkeypatch, tmp_path):
    monkeypatch.setattr(sweep_module, "run_scenario", FakeRun)
    FakeRun.output, FakeRun.interrupt_at, FakeRun.runs, FakeRun.seen = tmp_path, None, 0, []
    FakeRun.stop_reason = "interrupted"
    return FakeRun


def sweep_args(tmp_path: Path, *extra: str) -> list[str]:
    return [
        *("sim", "stand", "--sweep-push", "--workers", "1", "--connect", "tcp://127.0.0.1:9"),
        *("--output", str(tmp_path), *extra),
    ]


def leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(".partial"))


def test_the_files_are_written_after_every_finished_bisection(fake_runs, tmp_path, capsys):
    directions = ["--push-direction", "1", "0", "0", "--push-direction", "-1", "0", "0"]
    assert main(sweep_args(tmp_path, "--controller", "momentum", *directions)) == 0
    label = "+ linear and angular momentum"
    # Nothing before the first bisection ends; after it, its answer and "complete": false.
    assert fake_runs.seen[:10] == [None] * 10
    during = fake_runs.seen[10]
    assert during["complete"] is False
    assert during["unfinished"] == {label: ["(-1, 0, 0)"]}
    assert list(during["largest_survived_N"][label]) == ["(1, 0, 0)"]
    assert len(during["trials"][label]["(1, 0, 0)"]) == 10
    assert during["trials"][label]["(-1, 0, 0)"] == []
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["complete"] is True and written["unfinished"] == {}
    assert set(written["largest_survived_N"][label]) == {"(1, 0, 0)", "(-1, 0, 0)"}
    assert (tmp_path / "sweep_stand.png").read_bytes().startswith(b"\x89PNG")
    assert leftovers(tmp_path) == []
    printed = capsys.readouterr().out
    assert f"sweep: {tmp_path / 'sweep_stand.json'}; picture:" in printed


def test_a_stopped_sweep_keeps_its_finished_bisections_and_the_trials_of_the_next(
    fake_runs, tmp_path, capsys
):
    """Ctrl-C in the fifth trial of the second controller (one direction each)."""
    fake_runs.interrupt_at = 15
    assert main(sweep_args(tmp_path, "--push-direction", "-1", "0", "0")) == 130
    captured = capsys.readouterr()
    assert captured.err.strip() == "poise sim: interrupted"
    (row,) = [line for line in captured.out.splitlines() if line.startswith(FIRST_ROW)]
    assert "261.7" in row  # the first controller's row stays printed
    assert "(stopped: 1 of 4 bisections finished)" in captured.out
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["complete"] is False
    direction = "(-1, 0, 0)"
    assert written["largest_survived_N"][FIRST_ROW] == {direction: pytest.approx(261.71875)}
    assert len(written["trials"][FIRST_ROW][direction]) == 10
    # The stopped bisection: the four trials that gave an answer, not the interrupted one.
    stopped = written["trials"]["+ linear momentum"][direction]
    assert [t["force_N"] for t in stopped] == [2000.0, 1000.0, 500.0, 250.0]
    assert written["largest_survived_N"]["+ linear momentum"] == {}
    assert written["unfinished"] == {label: [direction] for label in list(written["trials"])[1:]}
    assert (tmp_path / "sweep_stand.png").read_bytes().startswith(b"\x89PNG")
    assert leftovers(tmp_path) == []


def test_a_sweep_stopped_before_any_bisection_finished_says_so(fake_runs, tmp_path, capsys):
    """The files of an earlier sweep in the directory are not left to pass for this one's."""
    (tmp_path / "sweep_stand.json").write_text('{"complete": true}')
    fake_runs.interrupt_at = 3
    args = sweep_args(tmp_path, "--controller", "prioritized", "--push-direction", "1", "0", "0")
    assert main(args) == 130
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["complete"] is False
    assert written["largest_survived_N"] == {"prioritized (de Lasa 2010)": {}}
    assert len(written["trials"]["prioritized (de Lasa 2010)"]["(1, 0, 0)"]) == 2


def test_a_trial_without_an_answer_stops_the_sweep_with_its_work_kept(fake_runs, tmp_path, capsys):
    fake_runs.interrupt_at, fake_runs.stop_reason = 12, "server stopped answering"
    directions = ["--push-direction", "1", "0", "0", "--push-direction", "-1", "0", "0"]
    assert main(sweep_args(tmp_path, "--controller", "momentum", *directions)) == 2
    assert "server stopped answering" in capsys.readouterr().err
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["complete"] is False
    (row,) = written["trials"].values()
    assert [len(trials) for trials in row.values()] == [10, 1]


def test_a_signal_while_the_files_are_written_waits_for_them(fake_runs, tmp_path, monkeypatch):
    """Ctrl-C in the middle of the first picture: it is finished, then the sweep stops.

    The signal is sent from another thread, which the kernel may pick to take it (a process
    pool's parent has such threads); Python still runs the handler in the main thread.
    """
    import os
    import threading

    import clients.sim.sweep_plot

    plot_sweep = clients.sim.sweep_plot.plot_sweep
    drawn = []

    def interrupted_plot(sweep, path):
        if not drawn:  # Python's SIGINT handler: a KeyboardInterrupt
            sender = threading.Thread(target=os.kill, args=(os.getpid(), signal.SIGINT))
            sender.start()
            sender.join()
        plot_sweep(sweep, path)
        drawn.append(sum(len(b.trials) for row in sweep.bisections.values() for b in row.values()))

    monkeypatch.setattr(clients.sim.sweep_plot, "plot_sweep", interrupted_plot)
    directions = ["--push-direction", "1", "0", "0", "--push-direction", "-1", "0", "0"]
    assert main(sweep_args(tmp_path, "--controller", "momentum", *directions)) == 130
    assert drawn == [10, 10]  # after the first bisection, then once more as the sweep stops
    assert fake_runs.runs == 10
    written = json.loads((tmp_path / "sweep_stand.json").read_text())
    assert written["complete"] is False and list(written["unfinished"].values()) == [["(-1, 0, 0)"]]
    assert leftovers(tmp_path) == []


def sweep_command(output: Path, *directions: str, workers: int = 1) -> list[str]:
    """The shortest real sweep: the momentum controller, a 10 ms push at 0.1 s (3.11 s trials).

    From behind (+x), 2000 N for 10 ms (20 N·s, half the robot's no-step bound) is survived:
    one trial. From the front (13.6 N·s bound) it is not: a full bisection, 10 trials.
    """
    return [
        *("sim", "stand", "--sweep-push", "--controller", "momentum", "--push-start", "0.1"),
        *("--push-duration", "0.01", "--workers", str(workers), "--output", str(output)),
        *(item for d in directions for item in ("--push-direction", *d.split())),
    ]


LABEL = "+ linear and angular momentum"


@pytest.mark.e2e
@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_sigterm_after_the_first_bisection_keeps_it(tmp_path, workers):
    """The acceptance of issue 40's first sweep item: a real sweep, stopped by SIGTERM."""
    output = tmp_path / "out"
    path = output / "sweep_stand.json"
    child = subprocess.Popen(
        [*POISE, *sweep_command(output, "1 0 0", "-1 0 0", workers=workers)],
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 300  # a bound for a busy machine, not a measurement
        while time.monotonic() < deadline and child.poll() is None and not path.exists():
            time.sleep(0.1)  # the first bisection (one trial) is done: the second runs on
        assert path.exists() and child.poll() is None, child.poll()
        child.send_signal(signal.SIGTERM)
        stdout, stderr = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == 130, stderr
    assert stderr.strip().splitlines()[-1] == "poise sim: interrupted"
    assert "Traceback" not in stderr
    written = json.loads(path.read_text())
    assert written["complete"] is False
    assert written["unfinished"] == {LABEL: ["(-1, 0, 0)"]}
    assert written["trials"][LABEL]["(1, 0, 0)"] == [{"force_N": 2000.0, "survived": True}]
    assert written["largest_survived_N"][LABEL] == {"(1, 0, 0)": 2000.0}
    assert (output / "sweep_stand.png").read_bytes().startswith(b"\x89PNG")
    assert "largest push survived" in stdout and "(stopped: 1 of 2 bisections finished)" in stdout
    assert leftovers(output) == []


@pytest.mark.e2e
@pytest.mark.slow
def test_a_sweep_run_to_the_end_is_complete(tmp_path):
    output = tmp_path / "out"
    done = run_poise(sweep_command(output, "1 0 0"), cwd=tmp_path, timeout_s=300)
    assert done.returncode == 0, done.stderr
    written = json.loads((output / "sweep_stand.json").read_text())
    assert written["complete"] is True and written["unfinished"] == {}
    assert written["trials"][LABEL]["(1, 0, 0)"] == [{"force_N": 2000.0, "survived": True}]
    assert f"sweep: {output / 'sweep_stand.json'}; picture:" in done.stdout
    assert leftovers(output) == []
