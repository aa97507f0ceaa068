"""Checks of the built-in MJCF models: generator parity, Pinocchio/MuJoCo agreement, stance."""

from __future__ import annotations

import importlib.util
import sys
from functools import cache
from pathlib import Path
from types import ModuleType

import mujoco
import numpy as np
import pinocchio as pin
import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA_DIR = ROOT / "controller_server" / "models" / "data"
GENERATOR_PATH = ROOT / "controller_server" / "models" / "build_mjcf.py"
MODEL_FILES = ("thesis_humanoid.xml", "revolute_humanoid.xml", "dino_biped.xml")
EXPECTED_NV = {"thesis_humanoid.xml": 45, "revolute_humanoid.xml": 28, "dino_biped.xml": 45}
MASS_RANGE_KG = {
    "thesis_humanoid.xml": (64.5, 65.5),
    "revolute_humanoid.xml": (50.0, 60.0),
    "dino_biped.xml": (40.0, 80.0),
}
TOL = 1e-9
BALL_AXES = "xyz"


def load_generator() -> ModuleType:
    """Import build_mjcf.py by path, independent of the package ``__init__`` files."""
    spec = importlib.util.spec_from_file_location("_poise_build_mjcf", GENERATOR_PATH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@cache
def mj_model(file_name: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(DATA_DIR / file_name))


@cache
def pin_model(file_name: str) -> pin.Model:
    return pin.buildModelFromMJCF(str(DATA_DIR / file_name))


def mj_default_data(file_name: str) -> mujoco.MjData:
    """MuJoCo data at qpos0 (the default standing pose) after kinematics and CoM."""
    model = mj_model(file_name)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return data


def pin_standing_q(model: pin.Model) -> np.ndarray:
    """Pinocchio configuration equal to MuJoCo's qpos0.

    Pinocchio drops the ``pos`` of a free-joint body (the root joint placement is the identity),
    so ``pin.neutral`` puts the pelvis at the world origin; the parser stores MuJoCo's default
    pose, pelvis height included, as ``referenceConfigurations["qpos0"]``.
    """
    return np.array(model.referenceConfigurations["qpos0"])


def mj_name(model: mujoco.MjModel, obj: mujoco.mjtObj, index: int) -> str:
    return mujoco.mj_id2name(model, obj, index)


def body_geom(model: mujoco.MjModel, body_id: int) -> int:
    (geom_ids,) = np.nonzero(model.geom_bodyid == body_id)
    assert len(geom_ids) == 1, f"body {mj_name(model, mujoco.mjtObj.mjOBJ_BODY, body_id)}"
    return int(geom_ids[0])


def mj_to_pin_q(mjm: mujoco.MjModel, pm: pin.Model, qpos: np.ndarray) -> np.ndarray:
    """Convert a MuJoCo qpos to a Pinocchio q, matching joints by name."""
    q = np.zeros(pm.nq)
    for j in range(1, pm.njoints):
        jid = mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_JOINT, pm.names[j])
        src, dst, nq = mjm.jnt_qposadr[jid], pm.idx_qs[j], pm.nqs[j]
        block = qpos[src : src + nq].copy()
        if nq == 7:  # free: (pos, w x y z) -> (pos, x y z w)
            block[3:] = np.roll(block[3:], -1)
        elif nq == 4:  # ball: (w x y z) -> (x y z w)
            block = np.roll(block, -1)
        q[dst : dst + nq] = block
    return q


def cross_2d(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull (Andrew's monotone chain)."""
    pts = sorted(map(tuple, points))

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while (
                len(out) >= 2
                and cross_2d(np.subtract(out[-1], out[-2]), np.subtract(p, out[-2])) <= 0
            ):
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def sole_corners_xy(file_name: str) -> np.ndarray:
    model, data = mj_model(file_name), mj_default_data(file_name)
    corners = []
    for side in ("left", "right"):
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{side}_sole")
        hx, hy, _ = model.site_size[sid]
        rot = data.site_xmat[sid].reshape(3, 3)
        for sx in (-1, 1):
            for sy in (-1, 1):
                corners.append(data.site_xpos[sid] + rot @ np.array([sx * hx, sy * hy, 0.0]))
    return np.array(corners)[:, :2]


def test_committed_files_match_generator() -> None:
    rendered = load_generator().render_all()
    assert sorted(rendered) == sorted(MODEL_FILES)
    for file_name, text in rendered.items():
        assert (DATA_DIR / file_name).read_text(encoding="utf-8") == text, file_name


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_structure_and_conventions(file_name: str) -> None:
    model, pm = mj_model(file_name), pin_model(file_name)
    assert model.nv == pm.nv == EXPECTED_NV[file_name]
    assert model.nq == pm.nq
    assert model.opt.timestep == 0.001
    np.testing.assert_array_equal(model.opt.gravity, [0.0, 0.0, -9.81])
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "root")
    assert model.jnt_type[root] == mujoco.mjtJoint.mjJNT_FREE
    assert mj_name(model, mujoco.mjtObj.mjOBJ_BODY, model.jnt_bodyid[root]) == "pelvis"
    assert pm.names[1] == "root" and pm.joints[1].shortname() == "JointModelFreeFlyer"
    for g in range(model.ngeom):
        if mj_name(model, mujoco.mjtObj.mjOBJ_GEOM, g) == "floor":
            assert model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE
            assert (model.geom_contype[g], model.geom_conaffinity[g]) == (0, 1)
            continue
        assert model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
        assert (model.geom_contype[g], model.geom_conaffinity[g]) == (1, 0)
    for b in range(1, model.nbody):  # one box per body, centered on the body's CoM
        g = body_geom(model, b)
        np.testing.assert_allclose(model.geom_pos[g], model.body_ipos[b], atol=TOL)
        np.testing.assert_allclose(model.geom_quat[g], [1, 0, 0, 0], atol=TOL)
        np.testing.assert_allclose(model.body_iquat[b], [1, 0, 0, 0], atol=TOL)


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_masses_and_inertias_agree(file_name: str) -> None:
    model, pm = mj_model(file_name), pin_model(file_name)
    total_kg = pin.computeTotalMass(pm)
    assert abs(total_kg - model.body_subtreemass[0]) < TOL
    lo_kg, hi_kg = MASS_RANGE_KG[file_name]
    assert lo_kg <= total_kg <= hi_kg
    for b in range(1, model.nbody):
        name = mj_name(model, mujoco.mjtObj.mjOBJ_BODY, b)
        frame = pm.frames[pm.getFrameId(name, pin.FrameType.BODY)]
        assert frame.placement.isIdentity(), name  # joint frame == body frame
        inertia = pm.inertias[frame.parentJoint]
        g = body_geom(model, b)
        box_m = 2 * model.geom_size[g]
        mass_kg = model.body_mass[b]
        expected = mass_kg / 12 * (np.sum(box_m**2) - box_m**2)  # solid box of uniform density
        assert mass_kg >= 0.2, name
        assert abs(inertia.mass - mass_kg) < TOL, name
        np.testing.assert_allclose(inertia.lever, model.body_ipos[b], atol=TOL)
        np.testing.assert_allclose(inertia.inertia, np.diag(model.body_inertia[b]), atol=TOL)
        np.testing.assert_allclose(model.body_inertia[b], expected, rtol=1e-9)
        assert np.all(model.body_inertia[b] > 0), name


def test_thesis_boxes_have_water_density() -> None:
    model = mj_model("thesis_humanoid.xml")
    for b in range(1, model.nbody):
        volume_m3 = np.prod(2 * model.geom_size[body_geom(model, b)])
        assert model.body_mass[b] / volume_m3 == pytest.approx(1000.0, rel=1e-9)


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_com_and_centroidal_inertia_agree(file_name: str) -> None:
    model, pm = mj_model(file_name), pin_model(file_name)
    data = mj_default_data(file_name)
    pd = pm.createData()
    q = pin_standing_q(pm)
    com = pin.centerOfMass(pm, pd, q)
    np.testing.assert_allclose(com, data.subtree_com[0], atol=TOL)
    pin.ccrba(pm, pd, q, np.zeros(pm.nv))
    inertia_mj = np.zeros((3, 3))
    for b in range(1, model.nbody):
        rot = data.ximat[b].reshape(3, 3)
        r = data.xipos[b] - data.subtree_com[0]
        inertia_mj += rot @ np.diag(model.body_inertia[b]) @ rot.T
        inertia_mj += model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    np.testing.assert_allclose(pd.Ig.inertia, inertia_mj, atol=TOL)


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_kinematics_agree_at_random_pose(file_name: str) -> None:
    model, pm = mj_model(file_name), pin_model(file_name)
    rng = np.random.default_rng(7)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    data.qpos[:3] += rng.uniform(-0.2, 0.2, 3)
    mujoco.mj_integratePos(model, data.qpos, rng.uniform(-0.5, 0.5, model.nv), 1.0)
    mujoco.mj_kinematics(model, data)
    pd = pm.createData()
    pin.framesForwardKinematics(pm, pd, mj_to_pin_q(model, pm, data.qpos))
    for b in range(1, model.nbody):
        frame_id = pm.getFrameId(mj_name(model, mujoco.mjtObj.mjOBJ_BODY, b), pin.FrameType.BODY)
        np.testing.assert_allclose(pd.oMf[frame_id].translation, data.xpos[b], atol=TOL)
        np.testing.assert_allclose(pd.oMf[frame_id].rotation, data.xmat[b].reshape(3, 3), atol=TOL)


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_default_pose_stands_on_floor(file_name: str) -> None:
    model, pm = mj_model(file_name), pin_model(file_name)
    q = pin_standing_q(pm)
    neutral = pin.neutral(pm)
    np.testing.assert_allclose(q[3:], neutral[3:], atol=TOL)  # only the base height differs
    pd = pm.createData()
    pin.framesForwardKinematics(pm, pd, q)
    for side in ("left", "right"):
        placement = pd.oMf[pm.getFrameId(f"{side}_sole")]
        assert abs(placement.translation[2]) < TOL
        np.testing.assert_allclose(placement.rotation, np.eye(3), atol=TOL)
    data = mj_default_data(file_name)
    for g in range(model.ngeom):
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
            continue
        rot = data.geom_xmat[g].reshape(3, 3)
        bottom_z = data.geom_xpos[g][2] - np.abs(rot[2]) @ model.geom_size[g]
        assert bottom_z >= -TOL, mj_name(model, mujoco.mjtObj.mjOBJ_GEOM, g)


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_sole_site_is_bottom_face_of_foot_box(file_name: str) -> None:
    model = mj_model(file_name)
    for side in ("left", "right"):
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{side}_sole")
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{side}_foot")
        assert model.site_bodyid[sid] == body
        assert model.site_type[sid] == mujoco.mjtGeom.mjGEOM_BOX
        g = body_geom(model, body)
        half = model.geom_size[g]
        np.testing.assert_allclose(model.site_size[sid], [half[0], half[1], 0.001], atol=TOL)
        np.testing.assert_allclose(
            model.site_pos[sid], model.geom_pos[g] - [0, 0, half[2]], atol=TOL
        )
        np.testing.assert_allclose(model.site_quat[sid], [1, 0, 0, 0], atol=TOL)
        np.testing.assert_allclose(model.geom_friction[g], [0.8, 0.005, 0.0001])


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_com_projects_inside_support_polygon(file_name: str) -> None:
    hull = convex_hull_2d(sole_corners_xy(file_name))
    com_xy = mj_default_data(file_name).subtree_com[0][:2]
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        assert cross_2d(b - a, com_xy - a) > 1e-3 * np.linalg.norm(b - a)  # >= 1 mm inside


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_each_motor_drives_exactly_its_dof(file_name: str) -> None:
    model = mj_model(file_name)
    data = mujoco.MjData(model)
    driven = np.zeros(model.nv, dtype=int)
    for a in range(model.nu):
        assert model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
        joint = model.actuator_trnid[a, 0]
        joint_name = mj_name(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        motor_name = mj_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        if model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_HINGE:
            assert motor_name == joint_name
            offset = 0
        else:
            assert model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_BALL
            assert motor_name[:-2] == joint_name and motor_name[-2] == "_"
            offset = BALL_AXES.index(motor_name[-1])
        expected = np.zeros(model.nv)
        expected[model.jnt_dofadr[joint] + offset] = 1.0
        data.ctrl[:] = 0.0
        data.ctrl[a] = 1.0
        mujoco.mj_forward(model, data)
        np.testing.assert_allclose(data.qfrc_actuator, expected, atol=1e-12, err_msg=motor_name)
        driven += expected.astype(int)
    np.testing.assert_array_equal(driven, [0] * 6 + [1] * (model.nv - 6))


@pytest.mark.parametrize("file_name", MODEL_FILES)
def test_torque_limits_and_joint_ranges(file_name: str) -> None:
    model = mj_model(file_name)
    for a in range(model.nu):
        lo_nm, hi_nm = model.actuator_ctrlrange[a]
        assert model.actuator_ctrllimited[a]
        assert np.isfinite(hi_nm) and hi_nm > 0 and lo_nm == -hi_nm
    for j in range(model.njnt):
        name = mj_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        lo, hi = model.jnt_range[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            assert model.jnt_limited[j] and np.isfinite([lo, hi]).all() and lo < hi, name
            assert lo <= 0.0 <= hi, name  # the default pose is feasible
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            assert model.jnt_limited[j] and lo == 0.0 and 0.0 < hi <= np.pi, name


@pytest.mark.parametrize("file_name", ["thesis_humanoid.xml", "revolute_humanoid.xml"])
def test_arms_hang_clear_of_the_torso(file_name: str) -> None:
    model, data = mj_model(file_name), mj_default_data(file_name)

    def aabb(g: int) -> tuple[np.ndarray, np.ndarray]:
        half = np.abs(data.geom_xmat[g].reshape(3, 3)) @ model.geom_size[g]
        return data.geom_xpos[g] - half, data.geom_xpos[g] + half

    names = [mj_name(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(model.ngeom)]
    arms = [g for g, n in enumerate(names) if "arm" in n or "shoulder" in n]
    trunk = [
        g
        for g, n in enumerate(names)
        if n.split("_box")[0] in ("pelvis", "abdomen", "chest", "torso")
    ]
    assert len(arms) >= 4 and len(trunk) >= 2
    for ga in arms:
        for gt in trunk:
            (a_lo, a_hi), (t_lo, t_hi) = aabb(ga), aabb(gt)
            assert np.any(a_lo >= t_hi - TOL) or np.any(t_lo >= a_hi - TOL), (names[ga], names[gt])


def test_revolute_knee_bends_backward_for_positive_angle() -> None:
    model = mj_model("revolute_humanoid.xml")
    data = mujoco.MjData(model)
    knee = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "left_knee")
    data.qpos[model.jnt_qposadr[knee]] = 1.0
    mujoco.mj_kinematics(model, data)
    shin = model.jnt_bodyid[knee]
    foot = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "left_foot")
    assert data.xpos[foot][0] < data.xpos[shin][0] - 0.2
