"""The 21 YCB-Video objects' facts (ids, extents, diameter, mass), recipes and colours.

What :mod:`handsim.world.registry` builds :data:`~handsim.world.registry.OBJECTS` from; each
recipe's shape is built in :mod:`handsim.world.ycbv_shapes`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from handsim.world.objects import Symmetry, _Geometry
from handsim.world.ycbv_shapes import (
    _banana,
    _bleach_cleanser,
    _bowl,
    _box,
    _box_shape,
    _can,
    _clamp,
    _marker,
    _mug,
    _mustard_bottle,
    _pitcher,
    _power_drill,
    _scissors,
)

__all__ = []


# (YCB-V id, name, extents x, y, z in mm, diameter mm, mass g). Masses: Calli et al. 2015.
_FACTS: tuple[tuple[int, str, tuple[float, float, float], float, float], ...] = (
    (1, "002_master_chef_can", (103, 140, 103), 172.2, 414),
    (2, "003_cracker_box", (164, 215, 72), 269.6, 411),
    (3, "004_sugar_box", (95, 177, 50), 198.4, 514),
    (4, "005_tomato_soup_can", (68, 102, 68), 120.7, 349),
    (5, "006_mustard_bottle", (97, 192, 59), 199.8, 603),
    (6, "007_tuna_fish_can", (86, 34, 86), 90.2, 171),
    (7, "008_pudding_box", (114, 90, 39), 142.6, 187),
    (8, "009_gelatin_box", (94, 78, 45), 114.4, 97),
    (9, "010_potted_meat_can", (102, 84, 58), 129.7, 370),
    (10, "011_banana", (179, 38, 109), 198.4, 66),
    (11, "019_pitcher_base", (189, 249, 133), 263.6, 178),
    (12, "021_bleach_cleanser", (103, 251, 68), 260.8, 1131),
    (13, "024_bowl", (161, 55, 161), 162.3, 147),
    (14, "025_mug", (120, 81, 94), 126.9, 118),
    (15, "035_power_drill", (184, 188, 58), 230.4, 895),
    (16, "036_wood_block", (90, 206, 91), 237.3, 729),
    (17, "037_scissors", (202, 98, 16), 204.1, 82),
    (18, "040_large_marker", (19, 121, 21), 121.5, 15.8),
    (19, "051_large_clamp", (173, 120, 39), 183.1, 125),
    (20, "052_extra_large_clamp", (210, 164, 52), 231.4, 202),
    (21, "061_foam_brick", (78, 51, 53), 102.9, 28),
)


def _with_symmetry(build: Callable[[], _Geometry], symmetry: Symmetry) -> Callable[[], _Geometry]:
    def wrapped() -> _Geometry:
        geom = build()
        geom.symmetry = symmetry
        return geom

    return wrapped


def _with_depth_symmetry(
    build: Callable[[], _Geometry], symmetry: Symmetry
) -> Callable[[], _Geometry]:
    """A shape symmetric in depth only (a plain can whose label breaks it in colour)."""

    def wrapped() -> _Geometry:
        geom = build()
        geom.depth_symmetry = symmetry
        return geom

    return wrapped


_Y_AXIS = Symmetry.continuous((0.0, 1.0, 0.0))

# name: (builder, shape description, rgba)
_RECIPES: dict[str, tuple[Callable[[], _Geometry], str, tuple[float, float, float, float]]] = {
    "002_master_chef_can": (
        _with_symmetry(functools.partial(_can, 51.5, 140.0, 172.2), _Y_AXIS),
        "cylinder r 51.5 mm along y, chamfered ends",
        (0.15, 0.3, 0.65, 1.0),
    ),
    "003_cracker_box": (
        functools.partial(_box, "003_cracker_box"),
        _box_shape("003_cracker_box"),
        (0.8, 0.15, 0.1, 1.0),
    ),
    "004_sugar_box": (
        functools.partial(_box, "004_sugar_box"),
        _box_shape("004_sugar_box"),
        (0.95, 0.9, 0.6, 1.0),
    ),
    "005_tomato_soup_can": (
        _with_depth_symmetry(functools.partial(_can, 34.0, 102.0, 120.7), _Y_AXIS),
        "cylinder r 34 mm along y, chamfered ends",
        (0.75, 0.1, 0.1, 1.0),
    ),
    "006_mustard_bottle": (
        _mustard_bottle,
        "lofted bottle: elliptic body, neck, cap",
        (0.95, 0.8, 0.1, 1.0),
    ),
    "007_tuna_fish_can": (
        _with_depth_symmetry(functools.partial(_can, 43.0, 34.0, 90.2), _Y_AXIS),
        "cylinder r 43 mm along y, chamfered ends",
        (0.55, 0.6, 0.7, 1.0),
    ),
    "008_pudding_box": (
        functools.partial(_box, "008_pudding_box"),
        _box_shape("008_pudding_box"),
        (0.5, 0.3, 0.15, 1.0),
    ),
    "009_gelatin_box": (
        functools.partial(_box, "009_gelatin_box"),
        _box_shape("009_gelatin_box"),
        (0.85, 0.2, 0.3, 1.0),
    ),
    "010_potted_meat_can": (
        functools.partial(_box, "010_potted_meat_can"),
        "rounded box 98 x 83 x 50 mm (r 6), tilted 5 deg",
        (0.2, 0.3, 0.7, 1.0),
    ),
    "011_banana": (
        functools.partial(_banana),
        "tapered tube along an arc; capsule chain",
        (0.95, 0.85, 0.3, 1.0),
    ),
    "019_pitcher_base": (_pitcher, "revolved open shell + handle", (0.2, 0.45, 0.8, 1.0)),
    "021_bleach_cleanser": (
        _bleach_cleanser,
        "lofted bottle: elliptic body, off-axis cap",
        (0.92, 0.92, 0.9, 1.0),
    ),
    "024_bowl": (_bowl, "revolved open shell on a flat foot", (0.8, 0.15, 0.15, 1.0)),
    "025_mug": (_mug, "revolved open shell + C handle", (0.75, 0.15, 0.12, 1.0)),
    "035_power_drill": (_power_drill, "barrel + chuck + grip + battery", (0.9, 0.75, 0.1, 1.0)),
    "036_wood_block": (
        functools.partial(_box, "036_wood_block", four_fold_axis=1),
        _box_shape("036_wood_block"),
        (0.75, 0.6, 0.4, 1.0),
    ),
    "037_scissors": (_scissors, "blade plates + handle loops", (0.2, 0.4, 0.8, 1.0)),
    "040_large_marker": (
        _marker,
        "cylinder r 9.5 mm along y + conical tip + cap clip",
        (0.1, 0.1, 0.1, 1.0),
    ),
    "051_large_clamp": (
        functools.partial(_clamp, 173.0, 120.0, 39.0),
        "two mirrored levers + spring pivot",
        (0.95, 0.5, 0.1, 1.0),
    ),
    "052_extra_large_clamp": (
        functools.partial(_clamp, 210.0, 164.0, 52.0),
        "two mirrored levers + spring pivot",
        (0.95, 0.45, 0.05, 1.0),
    ),
    "061_foam_brick": (
        functools.partial(_box, "061_foam_brick", four_fold_axis=0),
        _box_shape("061_foam_brick"),
        (0.8, 0.2, 0.15, 1.0),
    ),
}


_SYMMETRY_KINDS = {
    "002_master_chef_can": "continuous",
    "024_bowl": "continuous",
    "036_wood_block": "discrete",
    "040_large_marker": "continuous",
    "051_large_clamp": "discrete",
    "052_extra_large_clamp": "discrete",
    "061_foam_brick": "discrete",
}
