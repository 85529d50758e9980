"""Tests of the hand model: structure, geometry, physics and control, over every preset."""

import itertools

import mujoco
import numpy as np
import pytest

from handsim.errors import InvalidHandParams, UnknownName
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import (
    FINGER_OMEGA,
    FOREARM_GEOM,
    HAND_SIZES,
    UPPER_ARM_GEOM,
    Hand,
    HandParams,
    hand_params,
)
from handsim.hand.pose import FINGERS, JOINT_LIMITS, JOINT_NAMES, HandPose, joint_index
from handsim.hand.skin import ELBOW_RATIO, FOREARM_LENGTH_RATIO, build_skin, forearm_extension

PRESETS = list(itertools.product(HAND_SIZES, ("right", "left")))
MIRROR = np.array([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module", params=PRESETS, ids=[f"{s}-{h}" for s, h in PRESETS])
def preset_hand(request):
    """Every preset size x side, built and compiled once per module."""
    size, side = request.param
    hand = Hand(hand_params(size, side))
    return hand, hand.compile()


def _warnings(data: mujoco.MjData) -> dict[str, int]:
    return {
        mujoco.mjtWarning(i).name: int(data.warning[i].number)
        for i in range(len(data.warning))
        if data.warning[i].number
    }


def test_structure(preset_hand):
    """27 DoF, 21 actuators on the 21 hinges, 21 keypoint sites in order."""
    hand, model = preset_hand
    assert model.nv == 27
    assert model.nu == 21
    assert model.njnt == 22
    p = hand.prefix
    assert {model.joint(n).name for n in hand.joint_names} == {p + n for n in JOINT_NAMES}
    assert model.joint(hand.root_joint).type == mujoco.mjtJoint.mjJNT_FREE
    for i, name in enumerate(hand.actuator_names):
        assert model.actuator(name).trnid[0] == model.joint(p + JOINT_NAMES[i]).id
    sites = [model.site(n).name for n in hand.keypoint_site_names]
    assert sites == [f"{p}kp_{k}" for k in KEYPOINT_NAMES]


def test_joint_and_actuator_ranges_equal_the_limit_table(preset_hand):
    """Every hinge range and actuator ctrlrange is its own row of JOINT_LIMITS."""
    hand, model = preset_hand
    for i, name in enumerate(hand.joint_names):
        np.testing.assert_allclose(model.joint(name).range, JOINT_LIMITS[i], err_msg=name)
        np.testing.assert_allclose(
            model.actuator(hand.actuator_names[i]).ctrlrange, JOINT_LIMITS[i], err_msg=name
        )


def test_every_element_is_named_with_the_side_prefix(preset_hand):
    """No element is unnamed; every name carries the side prefix."""
    hand, model = preset_hand
    for kind, count in (
        (mujoco.mjtObj.mjOBJ_BODY, model.nbody),
        (mujoco.mjtObj.mjOBJ_JOINT, model.njnt),
        (mujoco.mjtObj.mjOBJ_GEOM, model.ngeom),
        (mujoco.mjtObj.mjOBJ_SITE, model.nsite),
        (mujoco.mjtObj.mjOBJ_ACTUATOR, model.nu),
        (mujoco.mjtObj.mjOBJ_EQUALITY, model.neq),
    ):
        first = 1 if kind == mujoco.mjtObj.mjOBJ_BODY else 0  # the world body
        for i in range(first, count):
            name = mujoco.mj_id2name(model, kind, i)
            assert name and name.startswith(hand.prefix), (kind, i, name)


def test_geom_groups_split_visual_and_collision(preset_hand):
    """Visual geoms are group 2 without contacts; collision geoms group 3; pads condim 4."""
    hand, model = preset_hand
    for i in range(model.ngeom):
        name = model.geom(i).name
        if "_visual_" in name:
            assert model.geom_group[i] == 2
            assert model.geom_contype[i] == 0 and model.geom_conaffinity[i] == 0
        else:
            assert "_collision_" in name
            assert model.geom_group[i] == 3
            assert model.geom_contype[i] == 1
            assert model.geom_condim[i] == (4 if "distal" in name else 3)


def test_hand_length_matches_request(preset_hand):
    """Wrist to middle fingertip, keypoints and skin, is the requested hand length within 1 %."""
    hand, model = preset_hand
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_pose(data, HandPose.neutral())
    kp = binding.keypoints(data)
    measured = np.linalg.norm(kp[KEYPOINT_NAMES.index("middle_tip")] - kp[0])
    assert measured == pytest.approx(hand.params.hand_length, rel=0.01)
    # The skin of the middle distal capsule ends at the tip keypoint.
    geom = model.geom(f"{hand.prefix}middle_distal_collision_0")
    tip_reach = data.geom_xpos[geom.id][1] + geom.size[1] + geom.size[0]
    assert tip_reach == pytest.approx(hand.params.hand_length, rel=0.01)


def test_a_kinematics_only_pose_places_the_hand_as_a_forwarded_one(preset_hand):
    """set_pose(kinematics_only=True) gives mj_forward's bodies, geoms and sites exactly."""
    hand, model = preset_hand
    binding = hand.bind(model)
    rng = np.random.default_rng(1)
    for _ in range(3):
        pose = HandPose(
            rng.uniform(-0.1, 0.1, 3),
            rng.uniform(-1, 1, 3),
            rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]),
        )
        full, kinematic = mujoco.MjData(model), mujoco.MjData(model)
        binding.set_pose(full, pose)
        binding.set_pose(kinematic, pose, kinematics_only=True)
        for field in ("xpos", "xmat", "geom_xpos", "geom_xmat", "site_xpos"):
            np.testing.assert_array_equal(getattr(kinematic, field), getattr(full, field))
        np.testing.assert_array_equal(binding.keypoints(kinematic), binding.keypoints(full))
        assert kinematic.ncon == 0  # no collision detection ran


def test_mass_is_human(preset_hand):
    """The hand with its forearm stub weighs what a human one does."""
    hand, model = preset_hand
    mass = model.body_subtreemass[model.body(hand.root_body).id]
    assert 0.3 < mass < 1.2  # hand (~0.6 % of body mass) plus a 10 cm forearm stub


def test_two_seconds_of_random_targets_without_warnings(preset_hand):
    """2 s of random wrist and finger targets raise no MuJoCo warning and stay finite."""
    hand, model = preset_hand
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_pose(data, HandPose.neutral(wrist_pos=(0, 0, 0.3)))
    rng = np.random.default_rng(0)
    for k in range(int(2.0 / model.opt.timestep)):
        if k % 50 == 0:  # a new target every 0.1 s
            angles = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
            wrist = np.array([0, 0, 0.3]) + rng.uniform(-0.05, 0.05, 3)
            binding.set_target(data, HandPose(wrist, rng.uniform(-0.5, 0.5, 3), angles))
        mujoco.mj_step(model, data)
    assert _warnings(data) == {}
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))


@pytest.mark.parametrize("abrupt", [False, True], ids=["natural-speed", "abrupt-steps"])
@pytest.mark.parametrize("digit", ["thumb", *FINGERS])
def test_actuation_respects_joint_limits(digit, abrupt):
    """Random targets on one digit (half beyond a limit) keep every joint within its limits.

    At natural speed (targets slewed at 25 rad/s, a 90 deg closure in 63 ms) the joints stay
    within 1 deg. Instantaneous target jumps of up to the whole range accelerate the light
    distal joints so hard that MuJoCo's soft limits give way transiently: within 5 deg.
    """
    hand = Hand(hand_params("large"))
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_pose(data, HandPose.neutral(wrist_pos=(0, 0, 0.3)))
    joints = [i for i, n in enumerate(JOINT_NAMES) if n.startswith(digit)]
    rng = np.random.default_rng(1)
    tolerance = np.deg2rad(5.0 if abrupt else 1.0)
    max_step = np.inf if abrupt else 25.0 * model.opt.timestep
    goal = np.zeros(21)
    target = np.zeros(21)
    for k in range(int(2.0 / model.opt.timestep)):
        if k % 50 == 0:
            goal[joints] = rng.uniform(JOINT_LIMITS[joints, 0] - 0.3, JOINT_LIMITS[joints, 1] + 0.3)
            goal = np.clip(goal, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        target += np.clip(goal - target, -max_step, max_step)
        binding.set_target(data, HandPose(np.array([0, 0, 0.3]), np.zeros(3), target))
        mujoco.mj_step(model, data)
        q = data.qpos[binding.joint_qpos]
        assert np.all(q >= JOINT_LIMITS[:, 0] - tolerance)
        assert np.all(q <= JOINT_LIMITS[:, 1] + tolerance)


def _step_response(hand, model, joint, start, step_deg):
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_pose(data, HandPose(np.zeros(3), np.zeros(3), start))
    target = start.copy()
    target[joint] += np.deg2rad(step_deg)
    binding.set_target(data, HandPose(np.zeros(3), np.zeros(3), target))
    trace = []
    for _ in range(int(0.2 / model.opt.timestep)):
        mujoco.mj_step(model, data)
        trace.append(data.qpos[binding.joint_qpos[joint]])
    fraction = (np.array(trace) - start[joint]) / np.deg2rad(step_deg)
    reached = np.nonzero(fraction >= 0.95)[0]
    t95 = (reached[0] + 1) * model.opt.timestep if reached.size else np.inf
    return t95, fraction.max() - 1.0


# Abduction steps (10 deg; the ranges are small) go away from the neighbour that is in the way
# (index, middle: radial; ring, little: ulnar); the fingers on that side are spread out first.
_ABD_STEP_DEG = {"index": 10.0, "middle": 10.0, "ring": -10.0, "little": -10.0}


@pytest.mark.parametrize("size", list(HAND_SIZES))
def test_step_response_of_every_joint(size):
    """95 % of a 30 deg flexion step within 60 ms, overshoot at most 5 %."""
    hand = Hand(hand_params(size))
    model = hand.compile()
    model.opt.gravity[:] = 0  # the wrist weld is not holding anything here
    for j, name in enumerate(JOINT_NAMES):
        start = np.zeros(21)
        if name.endswith("mcp_abd") and not name.startswith("thumb"):
            finger = name.split("_")[0]
            step = _ABD_STEP_DEG[finger]
            k = FINGERS.index(finger)
            others = FINGERS[:k] if step > 0 else FINGERS[k + 1 :]
            for other in others:
                limit = JOINT_LIMITS[joint_index(f"{other}_mcp_abd")]
                start[joint_index(f"{other}_mcp_abd")] = limit[1] if step > 0 else limit[0]
        elif name == "thumb_mcp_abd":
            step = 10.0
        else:
            step = 30.0
            start[j] = max(0.0, JOINT_LIMITS[j, 0])
        t95, overshoot = _step_response(hand, model, j, start, step)
        assert t95 <= 0.060, f"{name}: 95 % after {t95 * 1000:.0f} ms"
        assert overshoot <= 0.05, f"{name}: overshoot {overshoot:.1%}"


def test_gains_give_the_design_bandwidth():
    """No joint is faster than the design frequency, and every one is critically damped."""
    hand = Hand()
    model = hand.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    inertia = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, inertia)
    for name in hand.actuator_names:
        act = model.actuator(name)
        dof = model.jnt_dofadr[act.trnid[0]]
        kp, kv = act.gainprm[0], -act.biasprm[2]
        omega = np.sqrt(kp / inertia[dof, dof])
        assert omega <= FINGER_OMEGA * 1.001
        assert kv == pytest.approx(2.0 * np.sqrt(kp * inertia[dof, dof]), rel=1e-6)  # critical


def test_mirror_symmetry_of_left_and_right():
    """A left hand in the mirrored pose is the exact mirror image of the right hand."""
    rng = np.random.default_rng(3)
    right, left = Hand(HandParams(side="right")), Hand(HandParams(side="left"))
    models = right.compile(), left.compile()
    datas = [mujoco.MjData(m) for m in models]
    for _ in range(5):
        pose = HandPose(
            rng.normal(size=3) * 0.1,
            rng.normal(size=3),
            rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]),
        )
        right.bind(models[0]).set_pose(datas[0], pose)
        left.bind(models[1]).set_pose(datas[1], pose.mirrored())
        np.testing.assert_allclose(datas[1].site_xpos, datas[0].site_xpos * MIRROR, atol=1e-9)
        np.testing.assert_allclose(datas[1].geom_xpos, datas[0].geom_xpos * MIRROR, atol=1e-9)
    np.testing.assert_allclose(models[0].geom_size, models[1].geom_size)
    np.testing.assert_allclose(models[0].body_mass, models[1].body_mass)


def test_kinematic_set_pose_round_trip():
    """Kinematic mode writes a pose that reads back exactly, with targets set to match."""
    hand = Hand()
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    rng = np.random.default_rng(4)
    pose = HandPose(rng.normal(size=3), rng.uniform(-1, 1, 3), rng.uniform(*JOINT_LIMITS.T))
    binding.set_pose(data, pose)
    back = binding.pose(data)
    np.testing.assert_allclose(back.vector, pose.vector, atol=1e-12)
    np.testing.assert_allclose(data.ctrl, pose.angles)
    np.testing.assert_allclose(data.mocap_pos[binding.mocap_id], pose.wrist_pos)


def test_out_of_limit_targets_are_clamped():
    """Targets past a limit are clamped to it."""
    hand = Hand()
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_target(data, HandPose.from_angles({"index_pip_flex": 3.0}))
    assert data.ctrl[joint_index("index_pip_flex")] == pytest.approx(JOINT_LIMITS[7, 1])


def test_weld_drives_the_wrist_to_the_mocap_target():
    """The soft weld brings the free wrist to its mocap target."""
    hand = Hand()
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_pose(data, HandPose.neutral(wrist_pos=(0, 0, 0.3)))
    goal = HandPose.neutral(wrist_pos=(0.05, -0.03, 0.35), wrist_rotvec=(0.3, 0.0, 0.2))
    binding.set_target(data, goal)
    for _ in range(int(0.5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    reached = binding.pose(data)
    # Gravity sags the soft weld by a few millimetres; it must not drift further.
    assert np.linalg.norm(reached.wrist_pos - goal.wrist_pos) < 0.005
    assert np.linalg.norm(reached.wrist_rotvec - goal.wrist_rotvec) < 0.05


def test_coupled_dip_follows_two_thirds_of_pip():
    """With coupling, each DIP follows 2/3 of its PIP and has no actuator."""
    hand = Hand(HandParams(couple_dip=True))
    model = hand.compile()
    assert model.nu == 17
    assert not any("dip" in n for n in hand.actuator_names)
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    binding.set_pose(data, HandPose.neutral())
    binding.set_target(data, HandPose.from_angles({f"{f}_pip_flex": 1.2 for f in FINGERS}))
    for _ in range(int(0.3 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    for f in FINGERS:
        pip = data.qpos[binding.joint_qpos[joint_index(f"{f}_pip_flex")]]
        dip = data.qpos[binding.joint_qpos[joint_index(f"{f}_dip_flex")]]
        assert pip == pytest.approx(1.2, abs=0.05)
        assert dip == pytest.approx(2.0 / 3.0 * pip, abs=0.01)


def test_fk_of_the_skeleton_matches_the_model_sites():
    """NumPy FK of a non-default left hand equals MuJoCo's sites."""
    hand = Hand(HandParams(hand_length=0.2, side="left", thickness_scale=1.2))
    model = hand.compile()
    data = mujoco.MjData(model)
    pose = HandPose.from_angles({"thumb_cmc_abd": 0.5, "ring_pip_flex": 1.0})
    hand.bind(model).set_pose(data, pose)
    fk = ForwardKinematics(hand.skeleton).keypoints(pose)
    np.testing.assert_allclose(fk, hand.bind(model).keypoints(data), atol=1e-9)


def test_two_hands_share_a_scene():
    """A right and a left hand attach to one scene without name clashes."""
    scene = mujoco.MjSpec()
    right, left = Hand(HandParams(side="right")), Hand(HandParams(side="left"))
    right.attach_to(scene)
    left.attach_to(scene)
    model = scene.compile()
    assert model.nv == 54 and model.nu == 42 and model.nmocap == 2
    assert right.bind(model).root_qpos != left.bind(model).root_qpos


def test_bind_to_a_model_without_the_hand():
    """Binding to a model that lacks the hand names the missing side and the fix."""
    model = Hand(HandParams(side="left")).compile()
    with pytest.raises(UnknownName, match=r"does not contain the right hand \(prefix 'rh_'\)"):
        Hand().bind(model)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"hand_length": 0.3}, r"hand_length must be in \[0\.14, 0\.235\] m.*received 0\.3"),
        ({"hand_length": float("nan")}, r"hand_length must be in"),
        ({"side": "both"}, r"side must be 'right' or 'left'; received 'both'"),
        ({"palm_breadth": 0.15}, r"palm_breadth must be between 0\.35 and 0\.55 times"),
        ({"thickness_scale": 2.0}, r"thickness_scale must be in \[0\.7, 1\.4\]; received 2\.0"),
        ({"forearm": 1}, r"forearm must be True or False; received 1"),
    ],
)
def test_invalid_params(kwargs, message):
    """Every invalid parameter is refused with its valid range."""
    with pytest.raises(InvalidHandParams, match=message):
        HandParams(**kwargs)


def test_unknown_size_preset():
    """An unknown size preset lists the valid presets."""
    with pytest.raises(
        UnknownName, match=r"unknown hand size 'huge'; valid presets: small, medium"
    ):
        hand_params("huge")


def test_forearm_is_optional():
    """Without the forearm the hand loses its stub and the arm drawn beyond it.

    The stub is two capsules (visual + collision); the arm the forearm's mesh and the upper
    arm's capsule.
    """
    # The capsule look has one visual copy per collision capsule; the skin has one mesh per body.
    with_arm = Hand(HandParams(forearm=True, surface="capsules")).compile()
    without = Hand(HandParams(forearm=False, surface="capsules")).compile()
    assert with_arm.ngeom == without.ngeom + 6
    for name in (FOREARM_GEOM, UPPER_ARM_GEOM):
        assert with_arm.geom("rh_" + name).id >= 0
        with pytest.raises(KeyError):
            without.geom("rh_" + name)


@pytest.mark.parametrize("surface", ["skin", "capsules"])
def test_the_arm_is_drawn_only(surface):
    """The arm has no contact and no mass: bodies weigh and collide as without its geoms."""
    hand = Hand(HandParams(surface=surface))
    model = hand.spec.copy().compile()  # names unprefixed, as in the spec
    for name in (FOREARM_GEOM, UPPER_ARM_GEOM):
        g = model.geom(name).id
        assert (model.geom_contype[g], model.geom_conaffinity[g], model.geom_group[g]) == (0, 0, 2)
    bare = hand.spec.copy()
    for name in (FOREARM_GEOM, UPPER_ARM_GEOM):
        bare.delete(bare.geom(name))
    bare = bare.compile()
    for field in ("body_mass", "body_inertia", "body_ipos", "body_iquat", "body_subtreemass"):
        np.testing.assert_array_equal(getattr(model, field), getattr(bare, field), err_msg=field)
    collides = model.geom_contype > 0
    assert np.count_nonzero(collides) == np.count_nonzero(bare.geom_contype > 0)
    for field in ("geom_size", "geom_pos", "geom_quat", "geom_friction", "geom_bodyid"):
        np.testing.assert_array_equal(
            getattr(model, field)[collides], getattr(bare, field)[bare.geom_contype > 0], field
        )


@pytest.mark.parametrize(
    "params",
    [HandParams(), HandParams(side="left", hand_length=0.15, thickness_scale=0.8)],
    ids=["medium-right", "small-left-thin"],
)
def test_the_forearm_reaches_the_elbow_beyond_the_stub(params):
    """The forearm ends FOREARM_LENGTH_RATIO hand lengths from the wrist, past the stub.

    In line with the hand, it covers the end of the palm skin's stub: a closed tube of a few
    hundred triangles.
    """
    vertices, faces = forearm_extension(params)
    hl = params.hand_length
    assert vertices[:, 1].min() == pytest.approx(-FOREARM_LENGTH_RATIO * hl, abs=1e-12)
    assert vertices[:, 1].max() < 0.0  # proximal of the wrist crease
    assert len(faces) < 400
    # Closed, faces counter-clockwise from outside: a positive volume; every edge twice.
    tri = vertices[faces]
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    assert volume > 0.0
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    assert np.all(np.unique(edges, axis=0, return_counts=True)[1] == 2)
    # The stub's end (the palm skin's most proximal point) lies inside the forearm.
    palm = build_skin(params)[0]
    end = palm.vertices[np.argmin(palm.vertices[:, 1])]
    section_y = vertices[1:-1, 1]
    ring = vertices[1:-1][np.abs(section_y - end[1]) == np.abs(section_y - end[1]).min()]
    half_w, half_d = np.abs(ring[:, 0]).max(), np.abs(ring[:, 2]).max()
    assert np.hypot(end[0] / half_w, end[2] / half_d) < 1.0


@pytest.mark.parametrize("side", ["right", "left"])
def test_the_upper_arm_reaches_the_shoulder(side):
    """point_upper_arm runs the capsule from the elbow to the shoulder, in model and data."""
    hand = Hand(hand_params("medium", side))
    model = hand.compile()
    data = mujoco.MjData(model)
    binding = hand.bind(model)
    pose = HandPose.neutral(wrist_pos=(0.05, 0.0, 0.12), wrist_rotvec=(0.3, np.pi, 0.2))
    binding.set_pose(data, pose)
    shoulder = np.array([0.18, -0.55, 0.30])
    binding.point_upper_arm(data, shoulder)
    g = model.geom(hand.prefix + UPPER_ARM_GEOM).id
    axis = data.geom_xmat[g].reshape(3, 3)[:, 2]
    half = model.geom_size[g, 1]
    np.testing.assert_allclose(data.geom_xpos[g] + half * axis, shoulder, atol=1e-9)
    palm = model.body(hand.root_body).id
    elbow = data.xpos[palm] + data.xmat[palm].reshape(3, 3) @ (0, -ELBOW_RATIO * 0.189, 0)
    np.testing.assert_allclose(data.geom_xpos[g] - half * axis, elbow, atol=1e-9)
    # The model holds it too: a later forward draws the same capsule.
    xpos, xmat = data.geom_xpos[g].copy(), data.geom_xmat[g].copy()
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.geom_xpos[g], xpos, atol=1e-12)
    np.testing.assert_allclose(data.geom_xmat[g], xmat, atol=1e-12)


def test_hands_of_the_same_parameters_compile_to_the_same_model():
    """The actuator tuning is reused per parameters: equal armatures, gains and biases."""
    params = hand_params(0.201, "left")
    first, second = Hand(params).compile(), Hand(params).compile()
    for field in ("dof_armature", "actuator_gainprm", "actuator_biasprm", "body_mass"):
        np.testing.assert_array_equal(getattr(first, field), getattr(second, field), err_msg=field)
    other = Hand(hand_params(0.161, "left")).compile()
    assert not np.array_equal(first.actuator_gainprm, other.actuator_gainprm)


def test_the_skeleton_names_stay_importable_from_the_model():
    """``handsim.hand.model`` still exports the skeleton's names: the same objects."""
    from handsim.hand import model, skeleton

    assert set(model.__all__) == {
        "HandParams", "HAND_SIZES", "Skeleton", "SkeletonBody", "Capsule", "Box",
        "build_skeleton", "Hand", "HandBinding", "ACTUATOR_GAINS", "FINGER_OMEGA",
        "HAND_PHYSICS_OPTIONS", "hand_params", "FOREARM_GEOM", "UPPER_ARM_GEOM",
    }  # fmt: skip
    for name in (*skeleton.__all__, "HAND_LENGTH_RANGE_M"):
        assert getattr(model, name) is getattr(skeleton, name), name
