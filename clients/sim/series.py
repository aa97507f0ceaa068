"""A run's raw time series as NumPy arrays, for people who analyse in their own tools.

``poise sim/demo --series`` writes ``DIR/<scenario>.npz`` (``numpy.load``
reads it; every array has one row per control tick unless named
``diagnosed_*``). Keys, units and frames are those of the protocol
(docs/protocol.md):

- ``time_s``; the state sent: ``joint_position``, ``joint_velocity``,
  ``position_base_in_world``, ``orientation_base_in_world_xyzw``,
  ``linear_velocity_base_in_world``, ``angular_velocity_base_in_base``,
  ``contact_flags`` (bool, one column per contact);
- the command received: ``joint_torque``, ``joint_acceleration``,
  ``contact_wrench_in_world`` (ticks × contacts × 6);
- ``diagnosed_tick`` (the ticks whose command carries diagnostics) and, for
  those ticks, ``diagnosed_position_com_in_world``, ``diagnosed_center_of_pressure``,
  ``diagnosed_centroidal_moment_pivot``, ``diagnosed_linear_momentum``,
  ``diagnosed_angular_momentum``;
- ``dof_names`` (one per ``joint_torque`` column), ``contact_names``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clients.sim.plots import dof_names
from clients.sim.runner import RunRecord

__all__ = ["save_series", "series_arrays"]

STATE_FIELDS = (
    "joint_position",
    "joint_velocity",
    "position_base_in_world",
    "orientation_base_in_world_xyzw",
    "linear_velocity_base_in_world",
    "angular_velocity_base_in_base",
)
COMMAND_FIELDS = ("joint_torque", "joint_acceleration", "contact_wrench_in_world")
DIAGNOSTIC_FIELDS = (
    "position_com_in_world",
    "center_of_pressure",
    "centroidal_moment_pivot",
    "linear_momentum",
    "angular_momentum",
)


def series_arrays(record: RunRecord) -> dict[str, np.ndarray]:
    """The arrays of the module docstring, for a run of at least one tick."""
    arrays = {"time_s": np.asarray(record.time_s)}
    for name in STATE_FIELDS:
        arrays[name] = np.array([getattr(state, name) for state in record.states])
    arrays["contact_flags"] = np.array(record.contact_flags, dtype=bool)
    for name in COMMAND_FIELDS:
        arrays[name] = np.array([getattr(command, name) for command in record.commands])
    ticks = len(record.commands)
    arrays["contact_wrench_in_world"] = arrays["contact_wrench_in_world"].reshape(ticks, -1, 6)
    arrays["diagnosed_tick"] = np.array(record.diagnosed_ticks(), dtype=np.int64)
    diagnostics = record.diagnostics()
    for name in DIAGNOSTIC_FIELDS:
        arrays[f"diagnosed_{name}"] = np.array([getattr(d, name) for d in diagnostics])
    arrays["dof_names"] = np.array(dof_names(record.welcome.joints))
    arrays["contact_names"] = np.array([contact.name for contact in record.welcome.contacts])
    return arrays


def save_series(record: RunRecord, path: Path) -> Path:
    """Write :func:`series_arrays` to ``path`` (compressed ``.npz``); return the path."""
    np.savez_compressed(path, **series_arrays(record))  # type: ignore[arg-type]
    return path
