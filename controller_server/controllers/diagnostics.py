"""The diagnostics every controller reports, built once (``protocol.messages.Diagnostics``).

Every controller fills the same core (:class:`CoreDiagnostics`: the CM and the centroidal
momentum, desired and achieved momentum rates, COP and CMP, supports, residuals, saturated
joints) through :func:`core_diagnostics`, and adds its own extras under its name (``weighted``,
``prioritized``); :mod:`controller_server.wire` turns the whole into the wire message.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, TypedDict

import numpy as np

from controller_server.balance_points import ground_reference_points

__all__ = ["CoreDiagnostics", "core_diagnostics", "weighted_diagnostics", "with_extras"]


class CoreDiagnostics(TypedDict):
    """The core of a tick's diagnostics (wire names; docs/protocol.md has units and frames)."""

    position_com_in_world: np.ndarray
    velocity_com_in_world: np.ndarray
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray
    linear_momentum_rate_desired: np.ndarray
    linear_momentum_rate_achieved: np.ndarray
    angular_momentum_rate_desired: np.ndarray
    angular_momentum_rate_achieved: np.ndarray
    center_of_pressure: np.ndarray
    centroidal_moment_pivot: np.ndarray
    supports: list[bool]
    support_polygon_xy: np.ndarray
    objective_residuals: dict[str, float]
    constraint_residual: float
    root_wrench_residual: float
    saturated_joints: int


def core_diagnostics(
    *,
    position_com_in_world: np.ndarray,
    linear_momentum: np.ndarray,
    angular_momentum: np.ndarray,
    total_mass: float,
    momentum_rates_desired: tuple[np.ndarray, np.ndarray],
    momentum_rates_achieved: tuple[np.ndarray, np.ndarray],
    position_contact_frames_in_world: np.ndarray,
    contact_wrench_in_world: np.ndarray,
    supports: Sequence[bool],
    ground_height: float,
    support_polygon_xy: np.ndarray,
    objective_residuals: Mapping[str, float],
    constraint_residual: float,
    root_wrench_residual: float,
    saturated_joints: int,
) -> CoreDiagnostics:
    """The core, with the COP and CMP of the commanded ground wrenches (Macchietto eq. 5.17).

    Args:
        position_com_in_world: CM (m).
        linear_momentum: ``L`` (kg·m/s).
        angular_momentum: ``K`` about the CM (kg·m²/s).
        total_mass: ``m`` (kg).
        momentum_rates_desired: ``(L̇, K̇)`` the controller asked for (N, N·m).
        momentum_rates_achieved: ``(L̇, K̇)`` of the commanded acceleration (N, N·m).
        position_contact_frames_in_world: ``(contacts, 3)`` contact frame origins (m).
        contact_wrench_in_world: ``(contacts, 6)`` commanded ground wrenches (N, N·m).
        supports: Per contact, whether it supports.
        ground_height: Ground plane z (m).
        support_polygon_xy: ``(k, 2)`` vertices, counter-clockwise (m).
        objective_residuals: Per objective, its weighted residual.
        constraint_residual: ``‖C q̈ − d‖`` of the support equalities.
        root_wrench_residual: What the root's wrench misses of the equations of motion.
        saturated_joints: Joints whose torque reached its limit.
    """
    cop, cmp_ = ground_reference_points(
        position_contact_frames_in_world,
        position_com_in_world,
        contact_wrench_in_world,
        supports,
        ground_height,
    )
    return {
        "position_com_in_world": position_com_in_world,
        "velocity_com_in_world": linear_momentum / total_mass,
        "linear_momentum": linear_momentum,
        "angular_momentum": angular_momentum,
        "linear_momentum_rate_desired": momentum_rates_desired[0],
        "linear_momentum_rate_achieved": momentum_rates_achieved[0],
        "angular_momentum_rate_desired": momentum_rates_desired[1],
        "angular_momentum_rate_achieved": momentum_rates_achieved[1],
        "center_of_pressure": cop,
        "centroidal_moment_pivot": cmp_,
        "supports": list(supports),
        "support_polygon_xy": support_polygon_xy.reshape(-1),
        "objective_residuals": dict(objective_residuals),
        "constraint_residual": constraint_residual,
        "root_wrench_residual": root_wrench_residual,
        "saturated_joints": saturated_joints,
    }


def with_extras(core: CoreDiagnostics, controller: str, extras: dict[str, Any]) -> dict[str, Any]:
    """The core and a controller's own section (``weighted``, ``prioritized``)."""
    return {**core, controller: extras}


def weighted_diagnostics(
    total_mass: float, ground_height: float, flags: tuple[bool, ...], values: Mapping[str, Any]
) -> dict[str, Any]:
    """The weighted controllers' diagnostics from one tick's ``values`` (either kernel's).

    ``values``: the CM, momenta and their achieved rates, the optimizer's desired rates and
    β_ba, contact origins and commanded wrenches, the support polygon, the objectives'
    residuals at the commanded ``q̈``, the KKT's and the inverse dynamics' numbers, by the
    names :func:`core_diagnostics` and the ``weighted`` extras use.
    """
    core = core_diagnostics(
        position_com_in_world=values["position_com_in_world"],
        linear_momentum=values["linear_momentum"],
        angular_momentum=values["angular_momentum"],
        total_mass=total_mass,
        momentum_rates_desired=(
            values["linear_momentum_rate_desired"],
            values["angular_momentum_rate_desired"],
        ),
        momentum_rates_achieved=(values["linear_momentum_rate"], values["angular_momentum_rate"]),
        position_contact_frames_in_world=values["position_contact_frames_in_world"],
        contact_wrench_in_world=values["contact_wrench_in_world"],
        supports=flags,
        ground_height=ground_height,
        support_polygon_xy=values["support_polygon_xy"],
        objective_residuals=values["objective_residuals"],
        constraint_residual=values["constraint_residual"],
        root_wrench_residual=values["root_wrench_residual"],
        saturated_joints=values["saturated_joints"],
    )
    return with_extras(
        core,
        "weighted",
        {
            key: values[key]
            for key in (
                "optimizer_ran",
                "angular_momentum_weight",
                "objective_condition_number",
                "schur_condition_number",
                "objective_damping",
                "constraint_damping",
            )
        },
    )
