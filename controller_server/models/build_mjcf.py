"""Generate the three built-in MJCF robot models shipped in ``controller_server/models/data``.

The XML files are committed, but this script is their source of truth (a test checks that
the files equal :func:`render_all`). Edit the numbers here and regenerate with
``python -m controller_server.models.build_mjcf`` (or run this file directly).

Conventions shared by every model, chosen so that ``pinocchio.buildModelFromMJCF`` and
``mujoco.MjModel.from_xml_path`` read identical kinematics and inertias:

* SI units, z up, gravity -z, angles in radians. Body frames: x forward, y left, z up.
* Every body has exactly one box geom and an explicit ``<inertial>`` at the box center: a solid
  box of uniform density with full extents (a, b, c) has ``Ixx = m (b² + c²) / 12`` etc.
  Joints sit at their body's origin, so Pinocchio joint frames equal MuJoCo body frames.
* The root body ``pelvis`` (frame at the center of its box) has the free joint ``root``. In the
  default pose (hinges at 0, ball joints at the identity) legs are vertical, knees straight,
  and both soles lie exactly on z = 0.
* ``left_foot``/``right_foot`` carry box sites ``left_sole``/``right_sole`` at the center of the
  foot box's bottom face, with the foot box's x/y half extents and a 1 mm half thickness.
* Each hinge ``J`` is driven by ``<motor name="J" gear="1">``; each ball joint ``J`` by three
  motors ``J_x``, ``J_y``, ``J_z`` whose 6-vector gears pick the joint's local x, y, z axis.
  ``ctrlrange = [-L, L]`` where L is the torque limit in N·m.
* Robot geoms have contype=1, conaffinity=0 (they touch the floor, never each other).
* Pinocchio ignores the ``pos`` of the free-joint body, so ``pinocchio.neutral`` puts the pelvis
  at the origin (soles below the floor); the standing pose MuJoCo starts in is the parser's
  ``model.referenceConfigurations["qpos0"]`` (same joint angles, pelvis raised).

``thesis_humanoid`` scales de Leva's male segments to 65 kg and 1.70 m. Each box keeps the
segment length along the limb and a chosen width; its third extent is solved so that
``volume x 1000 kg/m³ = segment mass`` (the hand is merged into the forearm).

Hinge axis conventions of ``revolute_humanoid`` (all axes are +x, +y or +z of the body frame):

* ``*_yaw`` about +z (positive turns the toes / the torso / the face to the left);
* ``*_roll`` about +x (positive moves a hanging limb to the left, i.e. abduction on the left side
  and adduction on the right side; right-side roll and yaw ranges mirror the left ones);
* ``*_pitch``, ``*_knee``, ``*_elbow`` about +y. Positive pitch swings a hanging limb backward,
  so hip/shoulder flexion is negative; a positive knee angle bends the knee (shin backward),
  range [0, 2.4]; a positive ankle pitch points the toes down; a negative elbow angle flexes it.

Sources:
    de Leva, P. (1996). Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters.
    Journal of Biomechanics 29(9), 1223-1230, Table 4, male column (stature 1.741 m, 73 kg):
    segment mass fractions and the cervicale-based segment lengths used by ``thesis_humanoid``.
    Winter, D. A. (2009). Biomechanics and Motor Control of Human Movement, 4th ed., Fig. 4.1:
    foot breadth 0.055 H, used for the thesis model's sole width.
    Macchietto (2008 thesis) humanoid: 65 kg total, box links of water density, ball joints.
    The revolute robot and the dinosaur biped are this project's own designs; their torque limits
    are in the range published for current electric/hydraulic adult-size humanoids.
"""

from __future__ import annotations

import sys
from pathlib import Path

from controller_server.models.mjcf_writer import (
    Body,
    Joint,
    Vec3,
    pitch_quat,
    render,
    side,
    water_box_m,
)

__all__ = [
    "build_dino_biped",
    "build_revolute_humanoid",
    "build_thesis_humanoid",
    "main",
    "render_all",
]

DATA_DIR = Path(__file__).resolve().parent / "data"

THESIS_MASS_KG = 65.0
THESIS_STATURE_M = 1.70
DE_LEVA_STATURE_M = 1.741
#: segment -> (mass fraction of body mass, de Leva male length in m).
DE_LEVA_MALE = {
    "head": (0.0694, 0.2429),  # vertex - cervicale (head + neck)
    "upper_trunk": (0.1596, 0.2421),  # cervicale - xiphion
    "mid_trunk": (0.1633, 0.2155),  # xiphion - omphalion
    "lower_trunk": (0.1117, 0.1457),  # omphalion - mid hip joint centers
    "upper_arm": (0.0271, 0.2817),
    "forearm": (0.0162, 0.2689),
    "hand": (0.0061, 0.0862),
    "thigh": (0.1416, 0.4222),
    "shank": (0.0433, 0.4340),  # knee joint center - lateral malleolus
    "foot": (0.0137, 0.2581),  # heel - toe tip
}
THESIS_TORQUE_NM = {
    "back": 200.0,
    "neck": 40.0,
    "shoulder": 80.0,
    "elbow": 50.0,
    "hip": 250.0,
    "knee": 250.0,
    "ankle": 150.0,
}
THESIS_SWING_RAD = {
    "back": 0.6,
    "neck": 1.0,
    "shoulder": 2.6,
    "elbow": 2.5,
    "hip": 1.8,
    "knee": 2.4,
    "ankle": 0.8,
}


def _segment(name: str) -> tuple[float, float]:
    """Return (mass_kg, length_m) of a de Leva segment for the 65 kg, 1.70 m thesis subject."""
    fraction, length_m = DE_LEVA_MALE[name]
    return fraction * THESIS_MASS_KG, round(length_m * THESIS_STATURE_M / DE_LEVA_STATURE_M, 4)


def _ball(name: str, kind: str, limits: dict[str, float], swing: dict[str, float]) -> Joint:
    return Joint(name, "ball", (0.0, swing[kind]), limits[kind])


def build_thesis_humanoid() -> Body:
    """Build the 14-body, 13-ball-joint humanoid (nv = 45) of the Macchietto (2008) thesis."""
    tq, sw = THESIS_TORQUE_NM, THESIS_SWING_RAD
    hip_y_m, foot_breadth_m = 0.0875, round(0.055 * THESIS_STATURE_M, 4)
    (pelvis_kg, pelvis_m), (abdomen_kg, abdomen_m), (chest_kg, chest_m), (head_kg, head_m) = (
        _segment(n) for n in ("lower_trunk", "mid_trunk", "upper_trunk", "head")
    )
    (arm_kg, arm_m), (forearm_kg, forearm_m), (hand_kg, hand_m) = (
        _segment(n) for n in ("upper_arm", "forearm", "hand")
    )
    (thigh_kg, thigh_m), (shank_kg, shank_m), (foot_kg, foot_m) = (
        _segment(n) for n in ("thigh", "shank", "foot")
    )
    thigh_width_m, trunk_width_m, shoulder_y_m = 0.13, 0.30, 0.20
    foot_size = water_box_m(foot_kg, foot_m, foot_breadth_m, None)
    foot_height_m = foot_size[2]

    def leg(sign: float) -> Body:
        s = side(sign)
        # The ankle is a quarter of the foot length in front of the heel.
        foot = Body(
            f"{s}_foot",
            (0, 0, -shank_m),
            foot_size,
            foot_kg,
            (0.25 * foot_m, 0, -foot_height_m / 2),
            _ball(f"{s}_ankle", "ankle", tq, sw),
            sole=True,
        )
        shin = Body(
            f"{s}_shin",
            (0, 0, -thigh_m),
            water_box_m(shank_kg, None, 0.08, shank_m),
            shank_kg,
            (0, 0, -shank_m / 2),
            _ball(f"{s}_knee", "knee", tq, sw),
            [foot],
        )
        return Body(
            f"{s}_thigh",
            (0, sign * hip_y_m, -pelvis_m / 2),
            water_box_m(thigh_kg, None, thigh_width_m, thigh_m),
            thigh_kg,
            (0, 0, -thigh_m / 2),
            _ball(f"{s}_hip", "hip", tq, sw),
            [shin],
        )

    def arm(sign: float) -> Body:
        s = side(sign)
        lower_m = forearm_m + hand_m
        forearm = Body(
            f"{s}_forearm",
            (0, 0, -arm_m),
            water_box_m(forearm_kg + hand_kg, None, 0.065, lower_m),
            forearm_kg + hand_kg,
            (0, 0, -lower_m / 2),
            _ball(f"{s}_elbow", "elbow", tq, sw),
        )
        return Body(
            f"{s}_upper_arm",
            (0, sign * shoulder_y_m, chest_m - 0.03),
            water_box_m(arm_kg, None, 0.08, arm_m),
            arm_kg,
            (0, 0, -arm_m / 2),
            _ball(f"{s}_shoulder", "shoulder", tq, sw),
            [forearm],
        )

    head = Body(
        "head",
        (0, 0, chest_m),
        water_box_m(head_kg, None, 0.15, head_m),
        head_kg,
        (0, 0, head_m / 2),
        _ball("neck", "neck", tq, sw),
    )
    chest = Body(
        "chest",
        (0, 0, abdomen_m),
        water_box_m(chest_kg, None, trunk_width_m, chest_m),
        chest_kg,
        (0, 0, chest_m / 2),
        _ball("upper_back", "back", tq, sw),
        [head, arm(1), arm(-1)],
    )
    abdomen = Body(
        "abdomen",
        (0, 0, pelvis_m / 2),
        water_box_m(abdomen_kg, None, trunk_width_m, abdomen_m),
        abdomen_kg,
        (0, 0, abdomen_m / 2),
        _ball("lower_back", "back", tq, sw),
        [chest],
    )
    pelvis_z_m = foot_height_m + shank_m + thigh_m + pelvis_m / 2
    # Pelvis as wide as the two thighs side by side.
    pelvis_size = water_box_m(pelvis_kg, None, 2 * hip_y_m + thigh_width_m, pelvis_m)
    return Body(
        "pelvis",
        (0, 0, pelvis_z_m),
        pelvis_size,
        pelvis_kg,
        (0, 0, 0),
        None,
        [abdomen, leg(1), leg(-1)],
    )


# --------------------------------------------------------------------------------------------
# (b) Revolute humanoid: an adult-size electric humanoid robot, 6 hinges per leg.
# --------------------------------------------------------------------------------------------
#: joint kind -> (torque limit N·m, left-side range rad). Right roll/yaw ranges are mirrored.
REVOLUTE_JOINTS = {
    "hip_yaw": (120.0, (-0.5, 0.8)),
    "hip_roll": (150.0, (-0.4, 0.8)),
    "hip_pitch": (250.0, (-2.0, 0.6)),
    "knee": (300.0, (0.0, 2.4)),
    "ankle_pitch": (150.0, (-0.7, 0.9)),
    "ankle_roll": (100.0, (-0.4, 0.4)),
    "torso_yaw": (100.0, (-1.0, 1.0)),
    "neck_yaw": (20.0, (-1.2, 1.2)),
    "shoulder_pitch": (80.0, (-3.0, 1.0)),
    "shoulder_roll": (80.0, (-0.2, 2.8)),
    "shoulder_yaw": (60.0, (-1.5, 1.5)),
    "elbow": (40.0, (-2.5, 0.0)),
}
X_AXIS, Y_AXIS, Z_AXIS = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def _hinge(kind: str, axis: Vec3, sign: float | None = None) -> Joint:
    """Return the revolute-humanoid hinge ``kind`` (side-prefixed unless ``sign`` is None)."""
    torque_nm, (lo, hi) = REVOLUTE_JOINTS[kind]
    if sign is None:
        return Joint(kind, "hinge", (lo, hi), torque_nm, axis)
    if axis != Y_AXIS and sign < 0:  # mirror left roll/yaw ranges onto the right side
        lo, hi = -hi, -lo
    return Joint(f"{side(sign)}_{kind}", "hinge", (lo, hi), torque_nm, axis)


def build_revolute_humanoid() -> Body:
    """Build the 57.6 kg hinge-only humanoid (2 x 6 leg, 1 torso, 1 neck, 2 x 4 arm joints)."""
    ankle_height_m, shin_m, thigh_m, hip_drop_m, pelvis_half_m = 0.07, 0.40, 0.40, 0.09, 0.07

    def leg(sign: float) -> Body:
        s = side(sign)
        foot = Body(
            f"{s}_foot",
            (0, 0, 0),
            (0.24, 0.11, 0.04),
            1.2,
            (0.05, 0, -0.05),
            _hinge("ankle_roll", X_AXIS, sign),
            sole=True,
        )
        ankle = Body(
            f"{s}_ankle_pitch_link",
            (0, 0, -shin_m),
            (0.06, 0.06, 0.06),
            0.4,
            (0, 0, 0),
            _hinge("ankle_pitch", Y_AXIS, sign),
            [foot],
        )
        shin = Body(
            f"{s}_shin",
            (0, 0, -thigh_m),
            (0.09, 0.08, 0.37),
            3.0,
            (0, 0, -0.185),
            _hinge("knee", Y_AXIS, sign),
            [ankle],
        )
        thigh = Body(
            f"{s}_thigh",
            (0, 0, 0),
            (0.11, 0.10, 0.37),
            5.0,
            (0, 0, -0.215),
            _hinge("hip_pitch", Y_AXIS, sign),
            [shin],
        )
        roll = Body(
            f"{s}_hip_roll_link",
            (0, 0, -hip_drop_m),
            (0.10, 0.08, 0.06),
            1.0,
            (0, 0, 0),
            _hinge("hip_roll", X_AXIS, sign),
            [thigh],
        )
        return Body(
            f"{s}_hip_yaw_link",
            (0, sign * 0.10, -pelvis_half_m),
            (0.08, 0.08, 0.06),
            0.8,
            (0, 0, -0.03),
            _hinge("hip_yaw", Z_AXIS, sign),
            [roll],
        )

    def arm(sign: float) -> Body:
        s = side(sign)
        forearm = Body(
            f"{s}_forearm",
            (0, 0, -0.25),
            (0.06, 0.06, 0.28),
            1.2,
            (0, 0, -0.14),
            _hinge("elbow", Y_AXIS, sign),
        )
        upper = Body(
            f"{s}_upper_arm",
            (0, 0, 0),
            (0.07, 0.07, 0.22),
            1.6,
            (0, 0, -0.14),
            _hinge("shoulder_yaw", Z_AXIS, sign),
            [forearm],
        )
        roll = Body(
            f"{s}_shoulder_roll_link",
            (0, 0, -0.08),
            (0.07, 0.07, 0.06),
            0.5,
            (0, 0, 0),
            _hinge("shoulder_roll", X_AXIS, sign),
            [upper],
        )
        return Body(
            f"{s}_shoulder_pitch_link",
            (0, sign * 0.21, 0.36),
            (0.08, 0.06, 0.08),
            0.6,
            (0, 0, 0),
            _hinge("shoulder_pitch", Y_AXIS, sign),
            [roll],
        )

    head = Body(
        "head", (0, 0, 0.42), (0.16, 0.14, 0.18), 3.0, (0, 0, 0.11), _hinge("neck_yaw", Z_AXIS)
    )
    torso = Body(
        "torso",
        (0, 0, pelvis_half_m),
        (0.20, 0.34, 0.42),
        17.0,
        (0, 0, 0.21),
        _hinge("torso_yaw", Z_AXIS),
        [head, arm(1), arm(-1)],
    )
    pelvis_z_m = ankle_height_m + shin_m + thigh_m + hip_drop_m + pelvis_half_m
    return Body(
        "pelvis",
        (0, 0, pelvis_z_m),
        (0.16, 0.28, 2 * pelvis_half_m),
        7.0,
        (0, 0, 0),
        None,
        [torso, leg(1), leg(-1)],
    )


# --------------------------------------------------------------------------------------------
# (c) Dinosaur biped: horizontal body, neck and tail balance each other over the feet.
# --------------------------------------------------------------------------------------------
#: joint -> (torque limit N·m, max swing rad).
DINO_JOINTS = {
    "back": (300.0, 0.4),
    "neck_base": (100.0, 1.0),
    "neck_mid": (60.0, 1.0),
    "neck_top": (30.0, 1.0),
    "tail_base": (200.0, 0.6),
    "tail_mid": (100.0, 0.8),
    "tail_tip": (30.0, 0.8),
    "hip": (350.0, 1.6),
    "knee": (300.0, 2.4),
    "ankle": (150.0, 1.0),
}
DINO_NECK_PITCH_RAD = 0.7  # the neck rises 0.7 rad above the horizontal; the head is level


def _dino_ball(kind: str, sign: float | None = None) -> Joint:
    torque_nm, swing_rad = DINO_JOINTS[kind]
    name = kind if sign is None else f"{side(sign)}_{kind}"
    return Joint(name, "ball", (0.0, swing_rad), torque_nm)


def build_dino_biped() -> Body:
    """Build the ball-jointed dinosaur biped (pelvis, trunk, 2 neck links, head, 3 tail links)."""
    foot_height_m, shin_m, thigh_m, pelvis_half_m = 0.05, 0.40, 0.40, 0.11

    def leg(sign: float) -> Body:
        s = side(sign)
        foot = Body(
            f"{s}_foot",
            (0, 0, -shin_m),
            (0.30, 0.14, foot_height_m),
            1.5,
            (0.075, 0, -foot_height_m / 2),
            _dino_ball("ankle", sign),
            sole=True,
        )
        shin = Body(
            f"{s}_shin",
            (0, 0, -thigh_m),
            (0.10, 0.08, shin_m),
            3.0,
            (0, 0, -shin_m / 2),
            _dino_ball("knee", sign),
            [foot],
        )
        return Body(
            f"{s}_thigh",
            (0, sign * 0.13, -pelvis_half_m),
            (0.12, 0.10, thigh_m),
            5.0,
            (0, 0, -thigh_m / 2),
            _dino_ball("hip", sign),
            [shin],
        )

    head = Body(
        "head",
        (0.28, 0, 0),
        (0.32, 0.14, 0.14),
        3.5,
        (0.16, 0, 0),
        _dino_ball("neck_top"),
        quat=pitch_quat(DINO_NECK_PITCH_RAD),
    )
    neck_2 = Body(
        "neck_2",
        (0.30, 0, 0),
        (0.28, 0.10, 0.10),
        2.0,
        (0.14, 0, 0),
        _dino_ball("neck_mid"),
        [head],
    )
    neck_1 = Body(
        "neck_1",
        (0.50, 0, 0.06),
        (0.30, 0.12, 0.12),
        3.0,
        (0.15, 0, 0),
        _dino_ball("neck_base"),
        [neck_2],
        quat=pitch_quat(-DINO_NECK_PITCH_RAD),
    )
    trunk = Body(
        "trunk", (0.17, 0, 0), (0.50, 0.30, 0.32), 18.0, (0.25, 0, 0), _dino_ball("back"), [neck_1]
    )
    tail_3 = Body(
        "tail_3", (-0.45, 0, 0), (0.45, 0.07, 0.06), 2.0, (-0.225, 0, 0), _dino_ball("tail_tip")
    )
    tail_2 = Body(
        "tail_2",
        (-0.45, 0, 0),
        (0.45, 0.12, 0.10),
        6.0,
        (-0.225, 0, 0),
        _dino_ball("tail_mid"),
        [tail_3],
    )
    tail_1 = Body(
        "tail_1",
        (-0.17, 0, 0.03),
        (0.45, 0.18, 0.16),
        10.0,
        (-0.225, 0, 0),
        _dino_ball("tail_base"),
        [tail_2],
    )
    pelvis_z_m = foot_height_m + shin_m + thigh_m + pelvis_half_m
    return Body(
        "pelvis",
        (0, 0, pelvis_z_m),
        (0.34, 0.28, 2 * pelvis_half_m),
        10.0,
        (0, 0, 0),
        None,
        [trunk, tail_1, leg(1), leg(-1)],
    )


MODELS = {
    "thesis_humanoid": build_thesis_humanoid,
    "revolute_humanoid": build_revolute_humanoid,
    "dino_biped": build_dino_biped,
}


def render_all() -> dict[str, str]:
    """Return the XML text of every built-in model, keyed by file name."""
    return {f"{name}.xml": render(name, build()) for name, build in MODELS.items()}


def main() -> int:
    """Write every built-in model into ``controller_server/models/data``."""
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    for file_name, text in render_all().items():
        (DATA_DIR / file_name).write_text(text, encoding="utf-8", newline="\n")
        print(f"wrote {DATA_DIR / file_name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
