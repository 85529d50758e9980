"""Pictures: depth colour map, segmentation, skeletons, estimate against truth, MP4."""

import cv2
import numpy as np
import pytest

from handsim import viz
from handsim.estimator import Estimate
from handsim.frame import OCCLUDER_NONE, OCCLUDER_SELF, FrameRenderer
from handsim.hand.pose_sources import gesture
from handsim.world.camera import camera_preset
from handsim.world.scene import (
    OBJECT_LABEL_OFFSET,
    SEGMENT_LABELS,
    Scene,
    SceneSpec,
    sample_placements,
    third_person_camera,
)

K = np.array([[100.0, 0.0, 40.0], [0.0, 100.0, 30.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def frame():
    """One rendered frame of the open hand palm down over two objects."""
    rng = np.random.default_rng(0)
    camera = third_person_camera(camera_preset("icvl"), name="view")
    placements = sample_placements(rng, ("025_mug", "011_banana"))
    scene = Scene(SceneSpec(objects=placements, cameras=(camera,)))
    pose = gesture("open").replace(
        wrist_pos=np.array([0.0, -0.05, 0.15]), wrist_rotvec=np.array([0.0, np.pi, 0.0])
    )
    scene.reset(pose)
    with FrameRenderer(scene, "view") as renderer:
        return renderer.render(rng)


def _ramp(h=60, w=80):
    depth = np.tile(np.linspace(0.5, 1.5, w, dtype=np.float32), (h, 1))
    depth[:10, :10] = 0.0  # no measurement
    return depth


def test_depth_colormap_shape_scale_bar_and_units():
    """Colours run with depth, holes are black, the bar is appended; mm and (1, H, W) agree."""
    depth = _ramp()
    image = viz.depth_colormap(depth, near_m=0.5, far_m=1.5)
    assert image.shape == (60, 80 + viz.SCALE_BAR_WIDTH, 3) and image.dtype == np.uint8
    assert not image[:10, :10].any()  # holes
    assert not np.array_equal(image[30, 12], image[30, 79])  # near and far differ
    bar = image[:, 80:]
    assert bar.std() > 20  # colour ramp and tick labels
    plain = viz.depth_colormap(depth, near_m=0.5, far_m=1.5, scale_bar=False)
    assert plain.shape == (60, 80, 3)
    np.testing.assert_array_equal(plain, image[:, :80])
    mm = np.round(depth * 1000).astype(np.uint16)
    from_mm = viz.depth_colormap(mm[None], near_m=0.5, far_m=1.5, scale_bar=False)
    metres = viz.depth_colormap(mm.astype(np.float32) / np.float32(1000), near_m=0.5, far_m=1.5)
    np.testing.assert_array_equal(from_mm, metres[:, :80])
    near, far = viz.depth_range_m(depth)
    np.testing.assert_allclose((near, far), np.percentile(depth[depth > 0], [1, 99]))
    assert viz.depth_range_m(np.zeros((4, 4), np.float32)) == (0.0, 1.0)
    with pytest.raises(viz.InvalidImageInput, match=r"depth must be an \(H, W\).*received shape"):
        viz.depth_colormap(np.zeros((2, 3, 4, 5)))


def test_segmentation_colours_and_object_cycle():
    """Fixed labels take LABEL_BGR; object labels beyond the palette cycle through objects."""
    first = OBJECT_LABEL_OFFSET
    n_obj = len(viz.LABEL_BGR) - first
    labels = np.array(
        [[0, 1, 2, first - 1], [first, first + 1, first + n_obj, first + n_obj + 1]], np.int16
    )
    image = viz.draw_segmentation(labels)
    assert image.shape == (2, 4, 3) and image.dtype == np.uint8
    np.testing.assert_array_equal(image[0, 2], viz.LABEL_BGR[2])
    np.testing.assert_array_equal(image[1, 2], image[1, 0])  # wrapped to the first object
    np.testing.assert_array_equal(image[1, 3], image[1, 1])
    with pytest.raises(viz.InvalidImageInput, match="integer array"):
        viz.draw_segmentation(np.zeros((3, 3), np.float32))


def test_project_points_pinhole():
    """On the axis -> principal point; x = z -> fx to the right; behind the camera -> NaN."""
    uv = viz.project_points(K, [[0, 0, 1.0], [0.5, 0, 0.5], [0, 0, -1.0]])
    np.testing.assert_allclose(uv[0], (40, 30))
    np.testing.assert_allclose(uv[1], (140, 30))
    assert np.isnan(uv[2]).all()


def test_draw_skeleton_styles_at_keypoints():
    """Dots in the skeleton's colour where visible, red/yellow crosses where hidden, bones."""
    rng = np.random.default_rng(0)
    points = rng.uniform(10, 90, size=(21, 2)).round()
    black = np.zeros((100, 100, 3), np.uint8)
    visible = np.ones(21, bool)
    visible[[4, 8]] = False
    occluder = np.full(21, OCCLUDER_NONE)
    occluder[4], occluder[8] = 0, OCCLUDER_SELF
    out = viz.draw_skeleton(black, points, visible=visible, occluder=occluder, colour=(0, 255, 0))
    assert out.shape == black.shape and out.dtype == np.uint8 and not black.any()
    # The last drawn marker wins where points overlap: check keypoints with their own pixel.
    u, v = points[4].astype(int)
    assert tuple(out[v, u]) == viz.KEYPOINT_STYLES["object"][1]
    u, v = points[8].astype(int)
    assert tuple(out[v, u]) == viz.KEYPOINT_STYLES["self"][1]
    drawn = [tuple(out[int(q[1]), int(q[0])]) != (0, 0, 0) for q in points]
    assert all(drawn)
    a, b = viz.HAND_BONES[0]
    mid = ((points[a] + points[b]) / 2).round().astype(int)
    assert out[mid[1] - 1 : mid[1] + 2, mid[0] - 1 : mid[0] + 2].any()  # the bone passes here
    assert len(viz.HAND_BONES) == 21 and {i for bone in viz.HAND_BONES for i in bone} == set(
        range(21)
    )
    # Non-finite keypoints are skipped with their bones.
    points[0] = np.nan
    viz.draw_skeleton(black, points)
    with pytest.raises(viz.InvalidImageInput, match=r"keypoints_px must be \(21, 2\)"):
        viz.draw_skeleton(black, points[:5])


def test_draw_estimate_two_skeletons(frame):
    """Truth in green at the true keypoints; a shifted estimate in magenta where it projects."""
    truth = frame.keypoints_cam
    shift = np.array([0.03, 0.0, 0.0])
    estimate = Estimate(keypoints_cam=truth + shift)
    image = viz.draw_estimate(frame.depth, frame, estimate, title="Oracle(noise_mm=0)")
    h, w = frame.depth.shape
    assert image.shape == (h, w + viz.SCALE_BAR_WIDTH, 3) and image.dtype == np.uint8
    magenta = np.all(image == viz.ESTIMATE_BGR, axis=-1)
    estimate_px = viz.project_points(frame.K, truth + shift)
    hits = [magenta[int(round(v)), int(round(u))] for u, v in estimate_px if 0 <= u < w]
    assert np.mean(hits) > 0.8
    green = np.all(image == viz.TRUTH_BGR, axis=-1)
    visible = frame.visible & frame.in_frame
    assert visible.any()
    hits = [green[int(round(v)), int(round(u))] for u, v in frame.keypoints_px[visible]]
    assert np.mean(hits) > 0.5  # some are covered by the estimate's dots
    # At 2x the skeletons land on the magnified pixels.
    big = viz.draw_estimate(frame.depth, frame, estimate, upscale=2)
    assert big.shape == (2 * h, 2 * w + viz.SCALE_BAR_WIDTH, 3)
    magenta = np.all(big == viz.ESTIMATE_BGR, axis=-1)
    hits = [magenta[int(round(2 * v + 0.5)), int(round(2 * u + 0.5))] for u, v in estimate_px]
    assert np.mean(hits) > 0.8
    with pytest.raises(viz.InvalidImageInput, match="upscale must be an integer >= 1"):
        viz.depth_colormap(frame.depth, upscale=0)
    # A localizer: a ring at its centre; no estimate: a caption only.
    ring = viz.draw_estimate(frame.depth, frame, Estimate(center_cam=truth[9]))
    assert np.all(ring == viz.ESTIMATE_BGR, axis=-1).any()
    viz.draw_estimate(frame.depth, frame, None, scale_bar=False)


def test_outline_keeps_a_skeleton_visible_on_its_own_colour():
    """On a background of the skeleton's colour only a border shows it; the border is drawn."""
    points = np.random.default_rng(1).uniform(10, 90, size=(21, 2)).round()
    green = np.full((100, 100, 3), viz.TRUTH_BGR, np.uint8)
    plain = viz.draw_skeleton(green, points, colour=viz.TRUTH_BGR)
    assert np.array_equal(plain, green)  # the failure the border fixes: nothing to see
    bordered = viz.draw_skeleton(green, points, colour=viz.TRUTH_BGR, outline=(0, 0, 0))
    dark = bordered.sum(axis=-1) < 100
    assert dark.sum() > 200
    for u, v in points.astype(int):  # each keypoint keeps its colour, ringed by the border
        assert tuple(bordered[v, u]) == viz.TRUTH_BGR
        assert dark[v - 4 : v + 5, u - 4 : u + 5].any()


def test_draw_estimate_truth_shows_on_the_green_of_the_colour_map(frame):
    """Where turbo is green (mid-range depth), the true skeleton is outlined in black."""
    depth = np.where(frame.depth > 0, 0.5, 0.0).astype(np.float32)  # one mid-range colour
    image = viz.draw_estimate(depth, frame, None, near_m=0.3, far_m=0.7, scale_bar=False)
    background = viz.depth_colormap(depth, near_m=0.3, far_m=0.7, scale_bar=False)
    visible = frame.visible & frame.in_frame
    dark = image.sum(axis=-1) < 100
    for u, v in frame.keypoints_px[visible].round().astype(int):
        window = (slice(max(v - 5, 0), v + 6), slice(max(u - 5, 0), u + 6))
        assert dark[window].any() and not (background[window].sum(axis=-1) < 100).all()


def test_frame_legend_names_marks_and_colours():
    """The key of draw_frame: its width is the picture's; narrower pictures get it shrunk."""
    strip = viz.frame_legend(1280)
    assert strip.shape == (44, 1280, 3) and strip.dtype == np.uint8
    for style in ("object", "self"):  # the red and yellow crosses are drawn
        assert np.all(strip == viz.KEYPOINT_STYLES[style][1], axis=-1).any()
    palm = viz.LABEL_BGR[SEGMENT_LABELS.index("palm")].astype(np.uint8)
    assert np.all(strip == palm, axis=-1).any()
    assert viz.frame_legend(280).shape == (22, 280, 3)
    with pytest.raises(viz.InvalidImageInput, match="width must be an integer >= 1"):
        viz.frame_legend(0)


def test_draw_frame_panels(frame):
    """Depth with scale bar beside segmentation with the skeleton; needs the images."""
    panels = viz.draw_frame_panels(frame)
    h, w = frame.depth.shape
    assert panels.shape == (h, 2 * w + viz.SCALE_BAR_WIDTH, 3)
    labels = panels[:, w + viz.SCALE_BAR_WIDTH :]
    palm = viz.LABEL_BGR[SEGMENT_LABELS.index("palm")].astype(np.uint8)
    assert np.all(labels == palm, axis=-1).any()
    import dataclasses

    with pytest.raises(viz.InvalidImageInput, match="without images"):
        viz.draw_frame_panels(dataclasses.replace(frame, depth=None))


def test_video_writer_round_trip(tmp_path):
    """An MP4 decodes to the frames written (padded to 16-pixel blocks), colours kept."""
    imageio = pytest.importorskip("imageio.v2")
    path = tmp_path / "clip.mp4"
    with viz.VideoWriter(path, fps=10) as writer:
        for i in range(7):
            image = np.zeros((30, 50, 3), np.uint8)
            image[:, :, 2] = 200  # red in BGR
            cv2.putText(image, str(i), (5, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255))
            writer.append(image)
        with pytest.raises(viz.InvalidImageInput, match="first frame's shape"):
            writer.append(np.zeros((31, 50, 3), np.uint8))
    assert writer.n_frames == 7
    frames = [f for f in imageio.get_reader(str(path))]  # list() would ask len(): inf
    assert len(frames) == 7 and frames[0].shape == (32, 64, 3)
    red_rgb = frames[3][5:25, 30:45].reshape(-1, 3).mean(axis=0)
    assert red_rgb[0] > 150 and red_rgb[2] < 60  # decoded as RGB red
    with pytest.raises(viz.InvalidImageInput, match="fps must be a positive number"):
        viz.VideoWriter(tmp_path / "x.mp4", fps=0)
