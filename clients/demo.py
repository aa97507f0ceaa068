"""``poise demo``: a server, the scripted client, a plot and a summary.

Until the reference simulator arrives, the demo runs the scripted client
(:mod:`clients.scripted`): the thesis humanoid starts in a perturbed pose
and follows the controller's accelerations over ZeroMQ.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from clients.client import ControllerClient
from clients.scripted import ScriptedRun, run_scripted
from clients.server_process import ServerProcess

__all__ = ["plot_run", "run_demo"]

STANDARD_GRAVITY = 9.81


def plot_run(run: ScriptedRun, total_mass_kg: float, title: str, path: Path) -> None:
    """Write a four-panel PNG of a scripted run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_s = np.array(run.time_s)
    torque = np.array(run.joint_torque)
    figure, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    axes[0, 0].plot(time_s, np.degrees(run.pose_error_rad))
    axes[0, 0].set(title="Joint tracking error (RMS)", xlabel="time (s)", ylabel="deg")
    axes[0, 1].plot(time_s, np.abs(torque).max(axis=1), label="max |τ|")
    axes[0, 1].plot(time_s, np.sqrt(np.mean(torque**2, axis=1)), label="RMS τ")
    axes[0, 1].set(title="Joint torques", xlabel="time (s)", ylabel="N·m")
    axes[0, 1].legend()
    axes[1, 0].plot(time_s, run.vertical_force_N, label="Σ contact f_z")
    axes[1, 0].axhline(total_mass_kg * STANDARD_GRAVITY, color="k", ls="--", label="m g")
    axes[1, 0].set(title="Vertical ground force", xlabel="time (s)", ylabel="N")
    axes[1, 0].legend()
    axes[1, 1].hist(np.array(run.compute_time_s) * 1e3, bins=50)
    axes[1, 1].set(title="Server compute time per tick", xlabel="ms", ylabel="ticks")
    figure.suptitle(title)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def run_demo(
    model: str,
    output_dir: Path,
    duration_s: float,
    endpoint: str | None = None,
    controller: str = "momentum",
) -> int:
    """Run the demo and print a summary; returns the process exit code."""
    output_dir.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        if endpoint is None:
            print("starting `poise serve` on a free loopback port …", flush=True)
            endpoint = stack.enter_context(ServerProcess()).endpoint
        client = stack.enter_context(ControllerClient(endpoint, timeout_s=10.0))
        welcome = client.connect(model, controller=controller, client_name="poise demo")
        print(
            f"connected to {endpoint}: {welcome.model_name}, {welcome.total_mass:.1f} kg, "
            f"{sum(j.nv for j in welcome.joints)} actuated DoF, controller {welcome.controller}",
            flush=True,
        )
        run = run_scripted(client, duration_s=duration_s)
        stats = client.stats()

    plot_path = output_dir / "demo.png"
    title = f"{welcome.model_name}: {welcome.controller} controller over ZeroMQ (scripted client)"
    plot_run(run, welcome.total_mass, title, plot_path)
    compute_ms = np.array(run.compute_time_s) * 1e3
    summary = {
        "model": welcome.model_name,
        "ticks": len(run.time_s),
        "pose_error_start_deg": float(np.degrees(run.pose_error_rad[0])),
        "pose_error_end_deg": float(np.degrees(run.pose_error_rad[-1])),
        "max_abs_torque_Nm": float(np.abs(np.array(run.joint_torque)).max()),
        "vertical_force_over_weight_mean": float(
            np.mean(run.vertical_force_N) / (welcome.total_mass * STANDARD_GRAVITY)
        ),
        "compute_time_p50_ms": float(np.percentile(compute_ms, 50)),
        "compute_time_p99_ms": float(np.percentile(compute_ms, 99)),
        "server_ticks": stats[0].ticks if stats else 0,
        "plot": str(plot_path),
    }
    (output_dir / "demo.json").write_text(json.dumps(summary, indent=2))
    width = max(len(key) for key in summary)
    print("\n".join(f"  {key:<{width}}  {value}" for key, value in summary.items()))
    return 0
