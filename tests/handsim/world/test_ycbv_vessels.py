"""handsim.world.ycbv_vessels: the bowl, mug and pitcher shapes, split from ycbv_shapes."""

import numpy as np

from handsim.world import ycbv, ycbv_shapes, ycbv_vessels


def test_ycbv_shapes_still_exports_the_vessels_as_the_same_objects():
    """Every builder that moved is importable from ycbv_shapes, unchanged; ycbv uses them."""
    moved = [
        name
        for name, value in vars(ycbv_vessels).items()
        if callable(value) and getattr(value, "__module__", "") == ycbv_vessels.__name__
    ]
    assert set(moved) == {
        "_bowl",
        "_wall_sectors",
        "_zip_loops",
        "_orient",
        "_vessel",
        "_arc_2d",
        "_mug",
        "_pitcher",
    }
    for name in moved:
        assert getattr(ycbv_shapes, name) is getattr(ycbv_vessels, name), name
    for name in ("_bowl", "_mug", "_pitcher"):
        assert getattr(ycbv, name) is getattr(ycbv_vessels, name), name


def test_the_vessels_are_open_shells_with_a_cavity():
    """The mug's collision pieces leave its cavity empty; its handle sticks out on -x."""
    geom = ycbv_vessels._mug()
    assert geom.cavity is not None
    centres = np.array([p.centroid for p in geom.pieces])
    # No piece's centroid on the axis inside the cup (the floor's is at the bottom).
    inside = (np.hypot(centres[:, 0], centres[:, 2]) < 0.03) & (centres[:, 1] > -0.030)
    assert not inside.any()
    assert geom.visual.bounds[0, 0] < -0.047 - 0.020  # the handle, beyond the wall (r 47 mm)
