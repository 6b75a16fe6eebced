"""Drawing on omni frames (OpenCV): sectors, centre lines, foot and head marks (the paper's figure 1)."""

from __future__ import annotations

import cv2
import numpy as np

from omnijax import Rig, floor_radius, point_image_radius

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


def draw_detections(frame_rgb: np.ndarray, rig: Rig, dets, r_range: tuple[float, float],
                    label: str | None = None) -> np.ndarray:
    """A copy of ``frame_rgb`` with every valid detection drawn: sector edges (red), centre
    line (green), the person's radial extent (yellow), foot (cyan cross) and head (white circle)."""
    img = np.ascontiguousarray(frame_rgb.copy())
    omni = rig.omni
    r0, r1 = r_range
    valid = np.asarray(dets.valid)
    for k in np.nonzero(valid)[0]:
        tl, tr, tf = (float(np.asarray(getattr(dets, f))[k]) for f in ("theta_l", "theta_r", "theta_f"))
        for t in (tl, tr):
            cv2.line(img, _pt(omni, r0, t), _pt(omni, r1, t), RED, 1, cv2.LINE_AA)
        cv2.line(img, _pt(omni, r0, tf), _pt(omni, r1, tf), GREEN, 1, cv2.LINE_AA)
        r_in, r_out = float(np.asarray(dets.r_in)[k]), float(np.asarray(dets.r_out)[k])
        cv2.line(img, _pt(omni, r_in, tf), _pt(omni, r_out, tf), YELLOW, 2, cv2.LINE_AA)
        foot, head = foot_and_head_pixels(rig, float(np.asarray(dets.r_f)[k]), tf)
        cv2.drawMarker(img, foot, CYAN, cv2.MARKER_CROSS, 12, 2, cv2.LINE_AA)
        cv2.circle(img, head, 6, WHITE, 2, cv2.LINE_AA)
    if label:
        cv2.putText(img, label, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, WHITE, 1, cv2.LINE_AA)
    return img
