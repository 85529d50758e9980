"""What the expert grasps each object with: shape classes and grasp recipes.

A recipe (:class:`GraspRecipe`) names a strategy and a type of the GRASP taxonomy
(:data:`handsim.hand.pose_sources.GRASP_TYPES`) and the parameters the planner
(:mod:`.planning`) and the grip (:mod:`.execution`) read; the search itself is in
:mod:`.planning`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from handsim.envs.grasping.state import _LIFT_SPEED_M_S
from handsim.world.objects import YCBObject

__all__ = [
    "ShapeClass",
    "OBJECT_SHAPE_CLASSES",
    "GraspRecipe",
    "GRASP_RECIPES",
    "OBJECT_RECIPES",
    "grasp_recipe",
    "shape_class",
]

ShapeClass = Literal[
    "can", "bottle", "box", "disk", "vessel", "bowl", "tool", "flat_tool", "clamp", "elongated"
]


# Shape classes and recipes --------------------------------------------------------------------

OBJECT_SHAPE_CLASSES: dict[str, ShapeClass] = {
    "002_master_chef_can": "can",
    "003_cracker_box": "box",
    "004_sugar_box": "box",
    "005_tomato_soup_can": "can",
    "006_mustard_bottle": "bottle",
    "007_tuna_fish_can": "disk",
    "008_pudding_box": "box",
    "009_gelatin_box": "box",
    "010_potted_meat_can": "box",
    "011_banana": "elongated",
    "019_pitcher_base": "vessel",
    "021_bleach_cleanser": "bottle",
    "024_bowl": "bowl",
    "025_mug": "vessel",
    "035_power_drill": "tool",
    "036_wood_block": "box",
    "037_scissors": "flat_tool",
    "040_large_marker": "elongated",
    "051_large_clamp": "clamp",
    "052_extra_large_clamp": "clamp",
    "061_foam_brick": "box",
}
"""Shape class of each YCB-Video object (after the rpng/suo_slam labels)."""


@dataclasses.dataclass(frozen=True)
class GraspRecipe:
    """How the expert grasps one shape class.

    Attributes:
        strategy: ``"top"`` (palm down, thumb and fingers pinch across a horizontal axis),
            ``"side"`` (palm against the side of an upright object, the digits wrap around it)
            or ``"rim"`` (from the top, thumb outside and fingers inside a vessel's wall).
        grasp_type: key of :data:`handsim.hand.pose_sources.GRASP_TYPES`.
        fingers: the fingers whose pads oppose the thumb (``"index"`` ... ``"little"``).
        height_fraction: pad height as a fraction of the object's height (top, rim: from the
            table; side: height of the palm centre line).
        max_depth_m: top grasps: the pads go at most this far below the object's top, metres.
        min_depth_m: top grasps: and at least this far (the wrist rises to clear the table
            until the pads are there), metres.
        squeeze_rad: how far past first contact the fingers are driven (the joint that
            closes most; the others in proportion), radians.
        band_m: half width of the strip of object surface the pads close on, metres.
        contact_fraction: where the digits touch, along the distal capsule (0.5 the pad,
            1.0 the tip: for objects low on the table).
        wide: open from the hand's widest span instead of the grasp type's preshape.
        max_offset_m: also try grasp centres up to this far from the COM along the object's
            long axis (a narrower section there costs its offset), metres.
        finger_holes: the digits may enter holes wider than a fingertip (scissors loops)
            and pinch the material between them.
        min_grip_scale: the regulated grip never eases below this fraction of the squeeze's
            joint deflections (:class:`~handsim.envs.grasping.GraspExpert`).
        grip_margin: the grip force aimed at is this multiple of the expert's
            (:data:`~handsim.envs.grasping.execution.GRIP_SAFETY_FACTOR` times the load over the
            friction), in every phase.
        lift_grip_margin: and this multiple of it (on top of ``grip_margin``) while the grip
            settles and the object is lifted; the hold eases back.
        across_long_axis: top grasps: the pinch axis only square to the object's long axis
            (horizontal), the fingers away from the user (within ``max_yaw_rad``) and the
            object's longer end on the thumb's side of the hand; no other direction.
        max_yaw_rad: with ``across_long_axis``: how far the pinch axis (about the fingers'
            direction) may turn from pointing away from the user, (toward the thumb, away from
            it), radians.
        across_shift_m: with ``across_long_axis``: the pinch centre this far from the centre
            of mass toward the object's longer end, metres.
        hook: wide top grasps: the middle and ring fingers close as hooks (their PIPs and DIPs
            bent, the MCPs closing), so their distal pads come down the far wall about
            vertically.
        straight_fingers: fingers outside the pinch that stay straight above the object
            (slightly hyperextended at the MCP) instead of closing with the others.
        straight_fingers_deg: the fixed (MCP, PIP, DIP) flexion of ``straight_fingers``,
            degrees: straight (slightly hyperextended at the MCP) by default, or curled.
        pad_raises_m: top grasps: the pad heights tried above the deepest, metres.
        nominal_squeeze: top grasps: each joint's squeeze deflection times its nominal
            stiffness over its actuator's (at most 1), so that actuators stiffened for their
            bandwidth press with the nominal torque past contact.
        lift_speed_m_s: peak wrist speed of the lift, m/s.
        approach_obj: side wraps: the palm approaches along this direction of the object's
            frame (levelled), not away from the user; ``None``: away from the user.
        approach_cone_deg: side wraps: approach directions at most this far from the
            preferred one, degrees.
        max_from_user_deg: side wraps: and at most this far from pointing away from the
            user, degrees (past it, the reach from the user's side around the object is too
            long for the episode: the shape class's recipe is used instead).
        handle: side wraps of a vessel: wrap its handle (the points of the band farther from
            the cavity's axis than the wall), not its body; ``height_fraction`` is then not
            capped at the cans' 0.14 m.
    """

    strategy: Literal["top", "side", "rim"]
    grasp_type: str
    fingers: tuple[str, ...] = ("index", "middle")
    height_fraction: float = 0.5
    max_depth_m: float = 0.035
    min_depth_m: float = 0.004
    squeeze_rad: float = np.deg2rad(45.0)
    band_m: float = 0.012
    contact_fraction: float = 0.5
    wide: bool = False
    max_offset_m: float = 0.0
    finger_holes: bool = False
    min_grip_scale: float = 0.02
    grip_margin: float = 1.0
    lift_grip_margin: float = 1.0
    across_long_axis: bool = False
    max_yaw_rad: tuple[float, float] = (math.pi / 2.0, math.pi / 2.0)
    across_shift_m: float = 0.0
    hook: bool = False
    straight_fingers: tuple[str, ...] = ()
    straight_fingers_deg: tuple[float, float, float] = (-20.0, 0.0, 20.0)
    pad_raises_m: tuple[float, ...] = (0.0, 0.01, 0.02)
    nominal_squeeze: bool = False
    lift_speed_m_s: float = _LIFT_SPEED_M_S
    approach_obj: tuple[float, float, float] | None = None
    approach_cone_deg: float = 75.0
    max_from_user_deg: float = 180.0
    handle: bool = False


# Pad pinches of boxes and of thin objects at the table are sized for twice the hold's margin
# while the load comes off the table (the lift): with skin friction, the gelatin box is lifted
# with it and not without; the tripods need it too.
_LIFT_MARGIN = 2.0
# Tripods press fingertips near the top edge of thin objects, above and off their centre of
# mass: the weight also turns the object about the pinch, which point contacts hold by friction
# alone. Their grip has a larger margin in the hold as well.
_TRIPOD_MARGIN = 1.25
# Clamps: the thumb opposes the index and the middle finger together, so the planned pinch
# passes between them. With the index alone the middle finger,
# which closes beside it and pressed hardest, put the pinch 2-3 cm off the centre of mass (the
# extra-large clamp turned out of it in the lift).
_TRIPOD_FINGERS = ("index", "middle")
_LARGE_CLAMP_HOLD_MARGIN = 1.5
# Fingers outside a box's pinch, (MCP, PIP, DIP) in degrees: curled over the top face, as a
# hand holding a box with the whole hand keeps them, not straight out over it.
_CURLED_OVER_TOP_DEG = (0.0, 45.0, 30.0)

GRASP_RECIPES: dict[ShapeClass, GraspRecipe] = {
    "can": GraspRecipe("side", "large_diameter", height_fraction=0.45),
    # Bottles lower than cans (0.38 of the height, not 0.45): the thumb points up, and higher
    # its proximal segment reached the mustard bottle's sloping shoulder and pressed down on
    # it (normal 27 deg below the horizontal; skin friction, seeds 2, 3, 18 dropped, slipped
    # or not lifted; 20/20 at 0.38).
    "bottle": GraspRecipe("side", "large_diameter", height_fraction=0.38),
    "box": GraspRecipe(
        "top",
        "prismatic_4_finger",
        fingers=("middle",),
        contact_fraction=0.75,
        wide=True,
        lift_grip_margin=_LIFT_MARGIN,
    ),
    "disk": GraspRecipe("top", "prismatic_4_finger", lift_grip_margin=_LIFT_MARGIN),
    "vessel": GraspRecipe(
        "rim",
        "palmar_pinch",
        fingers=("index",),
        max_depth_m=0.02,
        squeeze_rad=float(np.deg2rad(25.0)),
    ),
    "bowl": GraspRecipe(
        "rim",
        "palmar_pinch",
        fingers=("index",),
        max_depth_m=0.02,
        squeeze_rad=float(np.deg2rad(25.0)),
    ),
    # The drill's fallback where its wrap is not planned (its own recipe below); measured with
    # the drill lying on its side: the pads at 0.3 of the height, not 0.5: with skin friction
    # the drill turned out of a
    # pinch higher on its body (seeds 0-1 not lifted or dropped; held with 0.3, seeds 0-9).
    # Squeezed with the nominal stiffnesses: the large hands' thumb CMC (4.9 N m/rad, not 3)
    # pressed 33 N against the index's 13 N, rolled the drill 15 deg in the squeeze and it
    # turned out of the pinch in the lift (large right hand, 17/20 at skin friction; 20/20).
    "tool": GraspRecipe("top", "prismatic_4_finger", height_fraction=0.3, nominal_squeeze=True),
    # The scissors keep the index alone: one finger enters a loop (with the index and the
    # middle finger together, 51 instead of 60 of 120 episodes over the six preset hands at
    # skin friction, 113 instead of about 107 at 1.0).
    "flat_tool": GraspRecipe(
        "top",
        "tripod",
        fingers=("index",),
        contact_fraction=1.0,
        finger_holes=True,
        max_offset_m=0.03,
        # Digits in the loops pinch 2.5 mm blades: eased further, they let the scissors turn
        # out of the pinch (seeds 0-1 dropped at 0.02, held at 0.15).
        min_grip_scale=0.15,
        squeeze_rad=float(np.deg2rad(30.0)),
        grip_margin=_TRIPOD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN,
    ),
    # Pads 5 mm above the deepest before 1 cm: where the arms of the extra-large clamp's X
    # keep the open hand from the deepest pinch, the large hands' thumbs pressed 1 cm higher
    # on the top edge (normal 18-37 deg above the horizontal) and the clamp turned out of the
    # pinch in the lift (large right and left hands, 13/20 each at skin friction; 20/20 each).
    "clamp": GraspRecipe(
        "top",
        "tripod",
        fingers=_TRIPOD_FINGERS,
        contact_fraction=1.0,
        grip_margin=_TRIPOD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN,
        pad_raises_m=(0.0, 0.005, 0.01, 0.02),
    ),
    "elongated": GraspRecipe(
        "top",
        "tripod",
        fingers=("index",),
        contact_fraction=1.0,
        band_m=0.008,
        grip_margin=_TRIPOD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN,
    ),
}
"""The grasp of each shape class."""

OBJECT_RECIPES: dict[str, GraspRecipe] = {
    # The drill upright on its battery, held as people hold it: the palm on the back of the
    # grip (approaching along the barrel, +x, toward the chuck), the digits wrapped around the
    # 34 x 38 mm grip, the thumb up toward the barrel and the index the highest finger, across
    # the grip's front under the barrel (the trigger). At 0.4 of the height the index's middle
    # phalanx lay on the grip's side 30 mm under the barrel (seeds 2-3, medium right hand); at
    # 0.46 across its front, 20 mm under it. Higher, the index meets the barrel, which
    # overhangs the back of the grip by 45 mm. Whichever way it faces: when its chuck points
    # at the user the reach goes around it to the back of the grip, and the hold then ends
    # 7.0-7.7 s into the 8 s episode (seeds 0-19, six preset hands, reach peak 0.45 m/s).
    "035_power_drill": GraspRecipe(
        "side",
        "small_diameter",
        height_fraction=0.46,
        approach_obj=(1.0, 0.0, 0.0),
        approach_cone_deg=20.0,
        max_from_user_deg=180.0,
    ),
    # The pitcher base by its handle, as people lift a pitcher: the palm on the handle's
    # outside (approaching along +x, toward the body), the fingers around the 18 mm tube
    # through the opening between it and the wall, the thumb up over the handle. The palm
    # centre line at 0.66 of the height (164 mm; the opening is 39-43 mm deep from 135 to
    # 180 mm, at least 26 mm from 90 to 210 mm): the index under the handle's upper bend
    # carries the load (at 0.62, 154 mm, the small left hand's grip let the pitcher pivot about
    # the handle, seeds 7, 17 slipped 10.4-10.6 mm; 20/20 at 0.66, 19/20 at 0.70). Whichever
    # way the handle faces: the rim pinch (the class's) swung out of 3 of 8 pinches with the
    # small right hand.
    "019_pitcher_base": GraspRecipe(
        "side",
        "small_diameter",
        height_fraction=0.66,
        approach_obj=(1.0, 0.0, 0.0),
        approach_cone_deg=20.0,
        max_from_user_deg=180.0,
        handle=True,
    ),
    # The banana is thick and round (38 mm high): pads below its equator (0.35 of its height)
    # press up under its flanks. At its equator the thumb met the upper flank (normal 12-18 deg
    # downward) and the pinch let go as the hold eased (seeds 9, 15, 19 at skin friction). The
    # 19 mm marker keeps its pads at its axis (lower: 17/20, higher: 11/20). Squeezed 30 deg
    # past contact, not 45: the fingertips under the far flank and the thumb's proximal segment
    # on the near one rolled the banana 25-27 deg and raised it 6 mm off the table in the
    # squeeze, and it turned out of the pinch in the lift or the hold (the medium left hand,
    # 15/20 at skin friction and at 0.5; 17 deg, 3 mm and 20/20 at 30 deg).
    "011_banana": dataclasses.replace(
        GRASP_RECIPES["elongated"], height_fraction=0.35, squeeze_rad=float(np.deg2rad(30.0))
    ),
    # The mug around its body from above (as the boxes: the thumb pad on the near wall, the
    # finger pads down the far wall, 0.6 of the height up, the handle out of the strip), not at
    # its rim. Not by its handle: the handle's opening (15 mm from the wall, 30 mm high) is
    # narrower than a finger of the preset hands. Not wrapped from the side (large diameter,
    # thumb up, as the cans): the mug is 81 mm tall and the medium and large palms are broader,
    # so the thumb closed over the rim into the mug and the mug was not lifted (large hands
    # 0/20, medium left 16/20 at skin friction). Held 1.5 times harder than the boxes (4.5
    # times its weight): the small hands span the 94 mm body with their pads' edges, and at
    # the boxes' margin the mug turned or slid out of 6 (right) and 9 (left) of 20 pinches.
    # Lifted at 1.3 times that, not the boxes' 2: from the lift's grip (up to 20 times the
    # weight) the hold eased for most of its window (median 5.8-6.8 times at friction 1.0).
    "025_mug": dataclasses.replace(
        GRASP_RECIPES["box"], height_fraction=0.6, grip_margin=1.5, lift_grip_margin=1.3
    ),
    # The scissors: the thumb and the index and middle pads across the loops' outer walls,
    # square to the long axis through the centre of mass (97 mm: the hand opens wide), when
    # the blades lie on the thumb's side of the hand. With the blades on the little finger's
    # side the middle finger meets the wall where it turns 31 deg toward the pivot and the
    # thumb presses down on the top edge, and at skin friction none of those were lifted;
    # there the shape class's pinch inside the loops. Pads planned at 0.4 of the height (the
    # table clearance raises the tips to about 11 mm); the large hands' longer fingers need
    # them 12-14 mm up, up to 2 mm under the top (at 4 mm they found no plan across). To keep
    # the blades on the thumb's side the wrist turns the fingers up to 135 deg from pointing
    # away from the user toward the thumb (the forearm across the body) and 120 deg the other
    # way, not 90: most pinches in the loops that failed lay there. The planned centre 3 mm
    # toward the pivot: the contacts land 3-4 mm toward the ends of the loops from it, and
    # planned at the centre of mass the pinch line passed behind it (the small hands dropped
    # them at friction 0.5, a 0.160 m hand at skin friction).
    "037_scissors": dataclasses.replace(
        GRASP_RECIPES["flat_tool"],
        fingers=("index", "middle"),
        height_fraction=0.4,
        wide=True,
        max_offset_m=0.0,
        finger_holes=False,
        across_long_axis=True,
        max_yaw_rad=(float(np.deg2rad(135.0)), float(np.deg2rad(120.0))),
        across_shift_m=0.003,
        min_depth_m=0.002,
    ),
    # The sugar box (38 mm high, pinched across 89 mm): the middle and ring fingers hooked
    # over the far wall, their pads on it with the thumb's on the near wall, 0.7 of the
    # height up (above the centre of mass, so the box hangs from the pinch). The box's
    # pinch closed the fingers along the prismatic grasp's curl: for the small hands their
    # middle segments met the far top edge first (normals 10-45 deg above the horizontal,
    # pushing the box down) and the index met the top face; at skin friction every episode
    # dropped it. The pads square on the walls need no lift margin (with the margin of 2 the
    # hold stopped easing at 7.9 times the weight, as the pinch turned in the compliant hand).
    # The index and little fingers, outside the pinch, are curled over the top face rather
    # than held straight out over the box.
    "004_sugar_box": dataclasses.replace(
        GRASP_RECIPES["box"],
        fingers=("middle", "ring"),
        height_fraction=0.7,
        lift_grip_margin=1.0,
        hook=True,
        straight_fingers=("index", "little"),
        straight_fingers_deg=_CURLED_OVER_TOP_DEG,
    ),
    # The cracker box's span grasp: the small hands' thumb tips reach only the rounded top edge
    # of the near wall (normal 13-16 deg below the horizontal once pressed), so at skin
    # friction the grip has less to spare than the pads' friction promises. Eased to the
    # boxes' aim in the hold (3.8 times the weight) the thumb slid at its friction limit and
    # the box fell; lifted at 0.25 m/s the box crept down in the palm and turned out of the
    # pinch about its long axis. Held 1.25 times harder (4.8 times the weight), lifted at
    # 0.12 m/s with the lift margin that keeps the lift's aim under 8 times the weight (7.5).
    "003_cracker_box": dataclasses.replace(
        GRASP_RECIPES["box"],
        grip_margin=1.25,
        lift_grip_margin=1.3,
        lift_speed_m_s=0.12,
    ),
    # The extra-large clamp (an X of 52 mm high walls): the ring and little fingers, outside
    # the tripod, stay straight above it. Closing with the others, the ring finger's proximal
    # segment of the small hands pressed on the X's top edge (34 N in the squeeze) while the
    # thumb met it with its proximal segment, and at skin friction the clamp fell as the hold
    # eased; the large hands did not lift it in 7 of 20 episodes. The lift's grip 1.4 times the
    # tripods': with the large right hand the X, pinched above its centre of mass, swung 35-50
    # deg about the pinch while it rose and was still turning when the hold began (seeds 14,
    # 15 turned 10.0-10.5 deg in the hold; 18/20 at the tripods' lift grip, 20/20 at 1.4x).
    "052_extra_large_clamp": dataclasses.replace(
        GRASP_RECIPES["clamp"],
        straight_fingers=("ring", "little"),
        lift_grip_margin=1.4 * _LIFT_MARGIN,
    ),
    # The large clamp (125 g): the hold's margin 1.5, not the tripods' 1.25 (the lift's aim
    # unchanged, 4 times the slip force). With the medium left hand the thumb's proximal segment
    # presses on the top edge, 20 mm above the centre of mass, and its pad at about 0.6 N:
    # the clamp hangs from three contacts above it and, with no torsional friction at skin
    # friction, turned out of the pinch as the hold eased from 12 N toward its 4.6 N aim
    # (seeds 15, 19 dropped at 5-6 N).
    "051_large_clamp": dataclasses.replace(
        GRASP_RECIPES["clamp"],
        grip_margin=_LARGE_CLAMP_HOLD_MARGIN,
        lift_grip_margin=_LIFT_MARGIN * _TRIPOD_MARGIN / _LARGE_CLAMP_HOLD_MARGIN,
    ),
}
"""Objects whose grasp differs from that of their shape class."""


def grasp_recipe(obj: YCBObject) -> GraspRecipe:
    """The recipe the expert grasps ``obj`` with: its own, else its shape class's."""
    return OBJECT_RECIPES.get(obj.name) or GRASP_RECIPES[shape_class(obj)]


def shape_class(obj: YCBObject) -> ShapeClass:
    """The shape class of an object: from the table for YCB objects, else from its size.

    Imported meshes are classed by their rested bounding box: taller than 0.12 m and narrower
    than 0.11 m is a bottle, an open cavity a bowl or vessel, otherwise a box.
    """
    if obj.name in OBJECT_SHAPE_CLASSES:
        return OBJECT_SHAPE_CLASSES[obj.name]
    rest = Rotation.from_quat(np.roll(obj.rest_quat_wxyz, -1))
    points = rest.apply(np.asarray(obj.model_points_m))
    size = points.max(axis=0) - points.min(axis=0)
    if obj.cavity_point_m is not None:
        return "bowl" if size[2] < 0.6 * min(size[0], size[1]) else "vessel"
    if size[2] > 0.12 and min(size[0], size[1]) < 0.11:
        return "bottle"
    return "box"
