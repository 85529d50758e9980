"""handsim.envs.viewer: render() for people, split from handsim.envs.base."""

from handsim.envs import base, viewer


def test_base_still_exports_the_viewer_names_as_the_same_objects():
    """Every name that moved is importable from base, unchanged; HandSimEnv renders with it."""
    moved = [
        name
        for name in vars(viewer)
        if name.startswith("_VIEWER") or name in ("_DEPTH_RENDER_MODES", "_SHADOW_LIGHT")
    ]
    assert len(moved) == 5
    for name in (*moved, "depth_colormap", "ViewerRendering"):
        assert getattr(base, name) is getattr(viewer, name), name
    assert "depth_colormap" in base.__all__
    for method in ("render", "viewer_clip_planes", "_frame_viewer", "_close_rgb"):
        assert getattr(base.HandSimEnv, method) is getattr(viewer.ViewerRendering, method)
