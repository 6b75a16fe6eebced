"""Drawing on omni frames (OpenCV): sectors, centre lines, foot and head marks, tracks with their
uncertainty ellipses, and the operator's view with the foveal inset (the paper's figure 1)."""

from __future__ import annotations

import cv2
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from omnijax import Rig, floor_radius, point_image_radius, world_to_image

RED, GREEN, YELLOW, CYAN, WHITE = (255, 40, 40), (40, 220, 40), (255, 220, 0), (0, 220, 255), (255, 255, 255)


def _pt(omni, r, theta) -> tuple[int, int]:
    x, y = omni.to_pixel(float(r), float(theta))
    return int(round(float(x))), int(round(float(y)))


def foot_and_head_pixels(rig: Rig, r_f: float, theta_f: float) -> tuple[tuple[int, int], tuple[int, int]]:
    """Pixels of the foot at (r_f, theta_f) and of the head centre above it (eq 1, then the head's height)."""
    omni = rig.omni
    R, _ = floor_radius(r_f, omni.r_m, omni.H_o, omni.profile)
    r_head = point_image_radius(R, rig.person.H_p - rig.person.R_h, omni.r_m, omni.H_o, omni.profile)
    return _pt(omni, r_f, theta_f), _pt(omni, r_head, theta_f)


@eqx.filter_jit
def detection_pixels(rig: Rig, dets, r0, r1):
    """Every detection's drawing in pixels, (K, 6, 2, 2): segments from/to for the two sector
    edges and the centre line (``r0`` to ``r1``), the person's radial extent, and (as degenerate
    segments) the foot and the head centre above it."""
    omni = rig.omni
    R, _ = floor_radius(dets.r_f, omni.r_m, omni.H_o, omni.profile)
    r_head = point_image_radius(R, rig.person.H_p - rig.person.R_h, omni.r_m, omni.H_o, omni.profile)
    r0, r1 = jnp.full_like(dets.r_f, r0), jnp.full_like(dets.r_f, r1)
    radii = jnp.stack([jnp.stack([r0, r1], -1)] * 3 + [jnp.stack([dets.r_in, dets.r_out], -1),
                      jnp.stack([dets.r_f, dets.r_f], -1), jnp.stack([r_head, r_head], -1)], 1)
    angles = jnp.stack([dets.theta_l, dets.theta_r] + [dets.theta_f] * 4, 1)[..., None]
    x, y = omni.to_pixel(radii, jnp.broadcast_to(angles, radii.shape))
    return jnp.stack([x, y], -1)


def draw_detections(frame_rgb: np.ndarray, rig: Rig, dets, r_range: tuple[float, float],
                    label: str | None = None) -> np.ndarray:
    """A copy of ``frame_rgb`` with every valid detection drawn: sector edges (red), centre
    line (green), the person's radial extent (yellow), foot (cyan cross) and head (white circle)."""
    img = np.ascontiguousarray(frame_rgb.copy())
    valid = np.asarray(dets.valid)
    px = np.round(np.asarray(detection_pixels(rig, dets, *r_range))).astype(np.int32)
    for k in np.nonzero(valid)[0]:
        seg = [tuple(map(tuple, s)) for s in px[k].tolist()]
        for (a, b), colour, width in zip(seg[:4], (RED, RED, GREEN, YELLOW), (1, 1, 1, 2)):
            cv2.line(img, a, b, colour, width, cv2.LINE_AA)
        cv2.drawMarker(img, seg[4][0], CYAN, cv2.MARKER_CROSS, 12, 2, cv2.LINE_AA)
        cv2.circle(img, seg[5][0], 6, WHITE, 2, cv2.LINE_AA)
    if label:
        cv2.putText(img, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, WHITE, 1, cv2.LINE_AA)
    return img


ORANGE, GREY, DARK = (255, 150, 0), (150, 150, 150), (18, 20, 24)
#: Points on each drawn uncertainty ellipse, and its size (standard deviations: 2.45 holds 95 % in 2-D).
ELLIPSE_POINTS, ELLIPSE_SD = 36, 2.45


@eqx.filter_jit
def floor_to_pixels(rig: Rig, xy, z):
    """Pixels (n, 2) of world points (X, Y) (n, 2) at heights ``z`` (n,) m (the configured rig)."""
    x, y = world_to_image(rig.omni, xy[:, 0], xy[:, 1], z)
    return jnp.stack([x, y], -1)


def ellipse_points(mean: np.ndarray, cov: np.ndarray, k: float = ELLIPSE_SD) -> np.ndarray:
    """Points (ELLIPSE_POINTS, 2) on the ``k``-sigma ellipse of a 2-D Gaussian."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    a = np.linspace(0, 2 * np.pi, ELLIPSE_POINTS)
    circle = np.stack([np.cos(a), np.sin(a)], -1)
    return mean + k * (circle * np.sqrt(np.maximum(w, 0.0))) @ v.T


def track_pixels(rig: Rig, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A track's drawing in pixels: its floor ellipse (ELLIPSE_POINTS, 2), foot, the tip of its
    velocity arrow (one second ahead) and its head (one compiled call)."""
    xy = np.concatenate([ellipse_points(x[:2], P[:2, :2]), [x[:2], x[:2] + x[2:], x[:2]]])
    z = np.zeros(len(xy))
    z[-1] = float(rig.person.H_p - rig.person.R_h)
    px = np.round(np.asarray(floor_to_pixels(rig, jnp.asarray(xy), jnp.asarray(z)))).astype(np.int32)
    return px[:ELLIPSE_POINTS], px[-3], px[-2], px[-1]


def draw_tracks(img: np.ndarray, rig: Rig, tracks, targets: dict[int, str]) -> np.ndarray:
    """Draw each track in place: its 95 % floor-position ellipse at the feet, id, and velocity;
    each target's head (``targets``: track id -> label, e.g. ``TARGET`` or the PTZs on it) gets a
    bracket and its label."""
    for tr in tracks:
        target = tr.id in targets
        colour = ORANGE if target else CYAN
        ellipse, foot, tip, head = track_pixels(rig, tr.x, tr.P)
        cv2.polylines(img, [ellipse], True, colour, 1, cv2.LINE_AA)
        cv2.arrowedLine(img, tuple(map(int, foot)), tuple(map(int, tip)), colour, 1, cv2.LINE_AA, tipLength=0.25)
        label = f"#{tr.id}" + (" face" if tr.captured else "")
        cv2.putText(img, label, (int(foot[0]) + 8, int(foot[1]) + 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, colour, 1,
                    cv2.LINE_AA)
        if target:
            x, y, s = int(head[0]), int(head[1]), 14
            for dx, dy in ((-1, -1), (1, -1), (-1, 1), (1, 1)):
                cv2.line(img, (x + dx * s, y + dy * s), (x + dx * (s - 6), y + dy * s), ORANGE, 2)
                cv2.line(img, (x + dx * s, y + dy * s), (x + dx * s, y + dy * (s - 6)), ORANGE, 2)
            cv2.putText(img, targets[tr.id], (x - 22, y - s - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, ORANGE, 1,
                        cv2.LINE_AA)
    return img


def _text(img, text, org, colour=WHITE, scale=0.45, thickness=1) -> None:
    """Text on a dark box (readable over any image)."""
    (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thickness)
    x, y = org
    box = img[max(y - h - 4, 0):y + base + 2, max(x - 4, 0):x + w + 4]
    box[:] = (0.35 * box).astype(np.uint8)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thickness, cv2.LINE_AA)


def compose_view(omni_img: np.ndarray, insets: list[tuple[np.ndarray | None, str]], title: str, clock: str,
                 lines: list[tuple[str, tuple[int, int, int]]]) -> np.ndarray:
    """The operator's view (the paper's figure 1): the annotated omni frame on the left, and on the
    right each PTZ's view (``insets``: (image or ``None``, label), in the rig's order; one fills the
    panel's width, several are tiled two or three to a row) above a status panel. ``lines`` are
    (text, colour) rows."""
    H, W = omni_img.shape[:2]
    pw = W // 2
    cols = 1 if len(insets) == 1 else 2 if len(insets) <= 4 else 3
    iw = pw // cols
    ih = iw * 3 // 4
    canvas = np.full((H, W + pw, 3), DARK, np.uint8)
    canvas[:, :W] = omni_img
    _text(canvas, title, (10, 20), WHITE, 0.5)
    _text(canvas, clock, (10, H - 12), WHITE, 0.45)
    cv2.circle(canvas, (W - 60, 16), 5, (230, 30, 30), -1, cv2.LINE_AA)
    _text(canvas, "LIVE", (W - 50, 21), (230, 30, 30), 0.45)
    scale = 0.45 if cols == 1 else 0.35
    for k, (inset, label) in enumerate(insets):
        x0, y0 = W + (k % cols) * iw, (k // cols) * ih
        if inset is not None:
            canvas[y0:y0 + ih, x0:x0 + iw] = cv2.resize(inset, (iw, ih), interpolation=cv2.INTER_AREA)
            c = (x0 + iw // 2, y0 + ih // 2)
            cv2.drawMarker(canvas, c, (255, 255, 255), cv2.MARKER_CROSS, 16 // cols, 1, cv2.LINE_AA)
        else:
            cv2.putText(canvas, "no foveal feed", (x0 + iw // 2 - 60 // cols, y0 + ih // 2), cv2.FONT_HERSHEY_SIMPLEX,
                        0.5 / cols, GREY, 1, cv2.LINE_AA)
        cv2.rectangle(canvas, (x0, y0), (x0 + iw - 1, y0 + ih - 1), GREY, 1)
        _text(canvas, label, (x0 + 8 // cols, y0 + 18 - 4 * (cols > 1)), WHITE, scale)
    cv2.line(canvas, (W, 0), (W, H), GREY, 1)
    y = -(-len(insets) // cols) * ih + 22
    for text, colour in lines:
        cv2.putText(canvas, text, (W + 10, y), cv2.FONT_HERSHEY_SIMPLEX, 0.42, colour, 1, cv2.LINE_AA)
        y += 19
    return canvas
