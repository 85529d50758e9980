"""Compiled per-pixel loops (numba): the renderer's read-back and the structured-light noise.

NumPy's version of these steps made a pass over the image per operation (some forty for the
noise, ten for the read-back), each a call of a few microseconds and a temporary array: most
of their time went to the calls and the memory traffic, not to the arithmetic. Each function
here is one or two passes. They compute in float32 as NumPy did (every constant is cast first:
numba promotes float32 with a Python float to float64), and draw no random numbers: the caller
draws them with the frame's generator, in the same order as before.

The first call in a process compiles them (about 2 s), or loads them from numba's cache
(``__pycache__`` beside this file, or ``NUMBA_CACHE_DIR``).
"""

from __future__ import annotations

import numba
import numpy as np

_JIT = {"nogil": True, "cache": True}


@numba.njit(**_JIT)
def depth_and_labels(
    rgb: np.ndarray,
    zbuffer: np.ndarray,
    c: np.float32,
    d: np.float32,
    table: np.ndarray,
    near_m: np.float32,
    far_m: np.float32,
    depth_m: np.ndarray,
    labels: np.ndarray,
) -> None:
    """Metric depth and a label per pixel from a segmentation render's read-back.

    Rows are flipped (OpenGL's buffer is bottom-up). A pixel whose red byte (segmentation
    colour index, fewer than 255 scene geoms) is 0 saw no geom; the others get the depth
    ``d / (buffer + c)`` and ``table[index]``. Background and depth outside
    ``[near_m, far_m]`` get depth 0 and ``table[0]``.

    Args:
        rgb: (H, W, 3) uint8 colour buffer, bottom-up.
        zbuffer: (H, W) float32 reversed-Z depth buffer, bottom-up.
        c: the depth map's offset (see ``render.DepthRenderer``).
        d: the depth map's scale, metres.
        table: (256,) label of each colour index, ``table[0]`` for background.
        near_m: nearest depth kept, metres.
        far_m: farthest depth kept, metres.
        depth_m: (H, W) float32, written, top-down.
        labels: (H, W) of ``table``'s dtype, written, top-down.
    """
    h, w = depth_m.shape
    zero = np.float32(0.0)
    background = table[0]
    for row in range(h):
        src = h - 1 - row
        for col in range(w):
            index = rgb[src, col, 0]
            if index != 0:
                z = d / (zbuffer[src, col] + c)
                if z >= near_m and z <= far_m:
                    depth_m[row, col] = z
                    labels[row, col] = table[index]
                    continue
            depth_m[row, col] = zero
            labels[row, col] = background


@numba.njit(**_JIT)
def jitter_lookup(
    cells: np.ndarray, table: np.ndarray, undecided: np.int32, out: np.ndarray, pending: np.ndarray
) -> int:
    """``out[i] = table[cells[i]]``; the indices whose entry is ``undecided`` go to ``pending``.

    Args:
        cells: (N,) uint8 random bytes.
        table: (256,) int32 packed displacement pair of each byte, or ``undecided``.
        undecided: the marker of a byte that straddles two pairs.
        out: (N,) int32 packed pairs, written.
        pending: (N,) int64, its first ``count`` entries written.

    Returns:
        count: the number of undecided pixels.
    """
    count = 0
    for i in range(cells.size):
        value = table[cells[i]]
        out[i] = value
        if value == undecided:
            pending[count] = i
            count += 1
    return count


@numba.njit(**_JIT)
def lit_pixels(
    clean: np.ndarray,
    r0: int,
    c0: int,
    offsets: np.ndarray,
    jitter: bool,
    shadow: bool,
    fb: np.float32,
    fx: np.float32,
    fy: np.float32,
    x: np.ndarray,
    y: np.ndarray,
    ray2: np.ndarray,
    max_step: float,
    max_secant2: np.float32,
    depth: np.ndarray,
    index: np.ndarray,
    z: np.ndarray,
    secant2: np.ndarray,
) -> int:
    """Steps 1, 2 and 4 of the structured-light model in a box of the image.

    1. Lateral jitter: ``depth[i, j] = clean[r0 + i + dv, c0 + j + du]``, clamped to the image.
    2. Projector shadow: pixel u is lit iff ``g(u) = fb / z(u) - u`` (``-u`` without depth)
       exceeds ``g`` of every pixel to its right in the row, a running maximum from the right.
       (A pixel more than ``d_max - d_min + 1`` columns away cannot claim it, so the whole
       rest of the row gives the same answer as that window.) Unlit pixels lose their depth.
    3. Grazing-angle dropout on the lit depth: ``1 / cos^2`` of the incidence from the four
       neighbours (see ``sensors._secant2_incidence``), 1 where there is no normal (a
       neighbour without depth or off the surface by more than ``max_step`` of the depth, or
       the box's border); pixels above ``max_secant2`` are dropped.

    Args:
        clean: (H, W) float32 clean depth, metres, 0 = none.
        r0: the box's first row in the image.
        c0: the box's first column in the image.
        offsets: (h, w, 2) int16 ``(du, dv)`` per box pixel (read when ``jitter``).
        jitter: apply step 1 (else the box of ``clean`` as is).
        shadow: apply step 2.
        fb: ``fx * baseline``, pixel metres.
        fx: focal length along u, pixels.
        fy: focal length along v, pixels.
        x: (H, W) float32 ``(u - cx) / fx``.
        y: (H, W) float32 ``(v - cy) / fy``.
        ray2: (H, W) float32 ``1 + x^2 + y^2``.
        max_step: see ``sensors.incidence_angle``.
        max_secant2: ``1 / cos^2`` of the largest incidence kept (``inf``: keep all).
        depth: (h, w) float32, written: the jittered, lit depth of the box.
        index: (h * w,) int64, its first ``count`` entries written: the kept pixels' flat
            indices in the box, in row-major order.
        z: (h * w,) float32, likewise: their depth, metres.
        secant2: (h * w,) float32, likewise: their ``1 / cos^2`` of the incidence.

    Returns:
        count: the number of kept pixels.
    """
    full_h, full_w = clean.shape
    h, w = depth.shape
    for i in range(h):
        for j in range(w):
            if jitter:
                u = min(max(c0 + j + offsets[i, j, 0], 0), full_w - 1)
                v = min(max(r0 + i + offsets[i, j, 1], 0), full_h - 1)
                depth[i, j] = clean[v, u]
            else:
                depth[i, j] = clean[r0 + i, c0 + j]
    zero = np.float32(0.0)
    if shadow:
        for i in range(h):
            running = np.float32(-np.inf)
            for j in range(w - 1, -1, -1):
                column = np.float32(c0 + j)
                zij = depth[i, j]
                g = fb / zij - column if zij > zero else -column
                if not g > running:
                    depth[i, j] = zero
                else:
                    running = g
    one = np.float32(1.0)
    low, high = np.float32(1.0 - max_step), np.float32(1.0 + max_step)
    count = 0
    for i in range(h):
        for j in range(w):
            centre = depth[i, j]
            if not centre > zero:
                continue
            s = one
            if 0 < i < h - 1 and 0 < j < w - 1:
                left, right = depth[i, j - 1], depth[i, j + 1]
                up, down = depth[i - 1, j], depth[i + 1, j]
                near = min(min(left, right), min(up, down))
                far = max(max(left, right), max(up, down))
                if near > zero and not near < centre * low and not far > centre * high:
                    p = fx * (right - left) / (right + left)
                    q = fy * (down - up) / (down + up)
                    n_z = x[r0 + i, c0 + j] * p + y[r0 + i, c0 + j] * q + one
                    s = (p * p + q * q + n_z * n_z) * ray2[r0 + i, c0 + j]
            if s > max_secant2:
                continue
            index[count] = i * w + j
            z[count] = centre
            secant2[count] = s
            count += 1
    return count


@numba.njit(**_JIT)
def disparity_noise(
    index: np.ndarray,
    z: np.ndarray,
    secant2: np.ndarray,
    normal: np.ndarray,
    fb: np.float32,
    step: np.float32,
    max_theta: np.float32,
    min_range_m: np.float32,
    max_range_m: np.float32,
    r0: int,
    c0: int,
    w: int,
    out: np.ndarray,
) -> None:
    """Step 3 and 5 for the kept pixels: noisy, quantized disparity, back to depth in range.

    The Gaussian's variance is Nguyen's ``sigma_z`` in disparity pixels (times
    ``d^2 / fb``) less the quantization's ``step^2 / 12``.

    Args:
        index: (n,) flat indices in the box, from :func:`lit_pixels`.
        z: (n,) depth, metres, likewise.
        secant2: (n,) ``1 / cos^2`` of the incidence, likewise.
        normal: (n,) float32 N(0, 1) draws.
        fb: ``fx * baseline``, pixel metres.
        step: disparity quantization step, pixels.
        max_theta: cap of the incidence angle in Nguyen's formula, radians.
        min_range_m: nearest depth measured, metres.
        max_range_m: farthest depth measured, metres.
        r0: the box's first row in the image.
        c0: the box's first column in the image.
        w: the box's width, pixels.
        out: (H, W) float32 zeros, written at the kept pixels.
    """
    half_pi = np.float32(np.pi / 2)
    step_var = step * step / np.float32(12.0)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    for k in range(index.size):
        zk = z[k]
        d = fb / zk
        theta = np.arctan(np.sqrt(np.abs(secant2[k] - one)))
        theta = min(theta, max_theta)
        ratio = theta / (half_pi - theta)
        offset = zk - np.float32(0.4)
        sigma = ratio * ratio / np.sqrt(zk) * np.float32(0.0001) + (
            offset * offset * np.float32(0.0019) + np.float32(0.0012)
        )
        sigma = sigma * (d * d) / fb
        variance = max(sigma * sigma - step_var, zero)
        noisy = normal[k] * np.sqrt(variance) + d
        noisy = np.float32(np.rint(noisy / step)) * step
        if noisy > zero:
            measured = fb / noisy
            if min_range_m <= measured <= max_range_m:
                i, j = divmod(index[k], w)
                out[r0 + i, c0 + j] = measured


@numba.njit(**_JIT)
def keypoint_visibility(
    depth_m: np.ndarray,
    labels: np.ndarray,
    z: np.ndarray,
    row: np.ndarray,
    col: np.ndarray,
    in_frame: np.ndarray,
    band: np.ndarray,
    parts: np.ndarray,
    neighbours: np.ndarray,
    object_offset: int,
    object_end: int,
    palm: int,
    occluder_self: int,
    occluder_scene: int,
    sensor_depth_m: np.ndarray,
    sensor_tolerance_m: float,
    visible: np.ndarray,
    occluder: np.ndarray,
    visible_sensor: np.ndarray,
) -> None:
    """Per-keypoint visibility and occluder from the clean render (``handsim.frame``).

    A pixel confirms keypoint k when it carries one of the keypoint's part labels and its depth
    lies within ``band[k]`` of the keypoint's; it blocks it when its depth is nearer than that.
    The keypoint is visible when its own pixel confirms it, or a neighbour does and its own
    pixel does not block it; a blocked, invisible keypoint's occluder is its pixel's object
    instance, ``occluder_self`` (the hand) or ``occluder_scene``. A visible keypoint is also
    seen by the sensor when one of the pixels that made it visible (its own, or else the
    confirming neighbours) has a sensor depth within ``sensor_tolerance_m`` of the clean one.

    Args:
        depth_m: (H, W) float32 clean depth, metres, 0 = none.
        labels: (H, W) int16 segmentation labels.
        z: (21,) keypoint depths, metres.
        row: (21,) keypoint pixel rows (integral floats).
        col: (21,) keypoint pixel columns (integral floats).
        in_frame: (21,) bool, keypoints inside the image.
        band: (21,) depth tolerance of each keypoint, metres.
        parts: (21, P) int16 labels each keypoint's surface may carry.
        neighbours: (9, 2) int (row, column) offsets, the pixel itself first.
        object_offset: label of object instance 0.
        object_end: the label after the last object's: the labels from it on are the person's
            other hand (a two-hand scene), a blocker among them is self-occlusion.
        palm: the lowest label of the person (the arm; the labels ``palm ..
            object_offset - 1`` are theirs): a blocker among them is self-occlusion.
        occluder_self: occluder code of the hand itself.
        occluder_scene: occluder code of the table or anything else.
        sensor_depth_m: (H, W) float32 depth the sensor returned, metres, 0 = none.
        sensor_tolerance_m: largest sensor-minus-clean depth difference that agrees, metres.
        visible: (21,) bool, written where ``in_frame`` (the caller fills False).
        occluder: (21,) int32, written where ``in_frame`` and hidden.
        visible_sensor: (21,) bool, written where ``in_frame`` (the caller fills False).
    """
    h, w = depth_m.shape
    for k in range(z.size):
        if not in_frame[k]:
            continue
        centre_blocked = False
        vis = False
        neighbour_confirms = False
        centre_label = 0
        centre_sensed = False
        neighbour_sensed = False
        for n in range(neighbours.shape[0]):
            r = min(max(np.intp(row[k]) + neighbours[n, 0], 0), h - 1)
            c = min(max(np.intp(col[k]) + neighbours[n, 1], 0), w - 1)
            seen = np.float64(depth_m[r, c])
            label = labels[r, c]
            own = False
            for p in range(parts.shape[1]):
                if label == parts[k, p]:
                    own = True
            confirms = own and seen > 0 and abs(seen - z[k]) <= band[k]
            sensed = False
            if confirms:
                measured = np.float64(sensor_depth_m[r, c])
                sensed = measured > 0 and abs(measured - seen) <= sensor_tolerance_m
            if n == 0:
                centre_label = label
                centre_blocked = seen > 0 and seen < z[k] - band[k]
                vis = confirms
                centre_sensed = sensed
            elif confirms:
                neighbour_confirms = True
                neighbour_sensed = neighbour_sensed or sensed
        if vis:
            visible_sensor[k] = centre_sensed
        else:
            vis = not centre_blocked and neighbour_confirms
            visible_sensor[k] = vis and neighbour_sensed
        visible[k] = vis
        if centre_blocked and not vis:
            if centre_label >= object_end:
                occluder[k] = occluder_self
            elif centre_label >= object_offset:
                occluder[k] = centre_label - object_offset
            elif centre_label >= palm:
                occluder[k] = occluder_self
            else:
                occluder[k] = occluder_scene
