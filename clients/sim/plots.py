"""PNG plots of a simulated run (matplotlib, no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clients.sim.runner import RunRecord

__all__ = ["plot_run"]


def plot_run(record: RunRecord, path: Path) -> None:
    """Four panels: CM/COP/CMP over the support polygon, CM height, momenta, torques."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    time_s = np.array(record.time_s)
    diagnostics = record.diagnostics()
    diagnosed_time_s = time_s[record.diagnosed_ticks()]
    com = np.array([d.position_com_in_world for d in diagnostics])
    cop = np.array([d.center_of_pressure for d in diagnostics])
    cmp_ = np.array([d.centroidal_moment_pivot for d in diagnostics])
    linear = np.array([d.linear_momentum for d in diagnostics])
    angular = np.array([d.angular_momentum for d in diagnostics])
    torque = np.array([c.joint_torque for c in record.commands])

    figure, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    top = axes[0, 0]
    polygon = diagnostics[0].support_polygon_xy.reshape(-1, 2)
    if len(polygon) >= 3:
        closed = np.vstack([polygon, polygon[:1]])
        top.fill(closed[:, 0], closed[:, 1], alpha=0.15, color="grey", label="support (t = 0)")
    top.plot(cop[:, 0], cop[:, 1], ".", ms=1.5, label="COP")
    top.plot(cmp_[:, 0], cmp_[:, 1], ".", ms=1.5, label="CMP")
    top.plot(com[:, 0], com[:, 1], "k-", lw=1.5, label="CM")
    top.set(title="Ground reference points (top view)", xlabel="x (m)", ylabel="y (m)")
    top.axis("equal")
    top.legend(loc="best", fontsize=8)

    axes[0, 1].plot(diagnosed_time_s, com[:, 2])
    axes[0, 1].set(title="CM height", xlabel="time (s)", ylabel="m")
    for push in record.scenario.pushes:
        for ax in axes.flat[1:]:
            ax.axvspan(push.start_s, push.start_s + push.duration_s, color="red", alpha=0.15)

    for i, axis in enumerate("xyz"):
        axes[1, 0].plot(diagnosed_time_s, linear[:, i], label=f"L{axis} (kg·m/s)")
        axes[1, 0].plot(diagnosed_time_s, angular[:, i], "--", label=f"H{axis} (kg·m²/s)")
    axes[1, 0].set(title="Momenta (red: pushes)", xlabel="time (s)")
    axes[1, 0].legend(fontsize=7, ncol=2)

    axes[1, 1].plot(time_s, np.abs(torque).max(axis=1), label="max |τ|")
    axes[1, 1].plot(time_s, np.sqrt(np.mean(torque**2, axis=1)), label="RMS τ")
    axes[1, 1].set(title="Joint torques", xlabel="time (s)", ylabel="N·m")
    axes[1, 1].legend()

    status = f"fell at {record.fall_time_s:.2f} s" if record.fell else "stayed up"
    figure.suptitle(
        f"{record.scenario.name} — {record.scenario.controller} controller, "
        f"{record.scenario.backend} backend: {status}"
    )
    figure.savefig(path, dpi=100)
    plt.close(figure)
