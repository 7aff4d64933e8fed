"""Drawing results onto a photo, like the paper's results figure: outline, keypoints, pose
axes and the decoded payload of every detection."""

from __future__ import annotations

import cv2
import numpy as np

from deepmorph_core.payload import format_payload
from deepmorph_detect.results import Located


def draw_overlay(image: np.ndarray, detections: list[Located]) -> np.ndarray:
    """A BGR copy of ``image`` with each detection drawn on it.

    Verified payloads are green, unverified ones red. Pose axes are half a drawing width
    long: x red, y green, z (out of the paper, towards the camera) blue.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = np.clip(img * 255, 0, 255).astype(np.uint8)
    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img[..., :3].copy()
    scale = max(1.0, max(out.shape[:2]) / 640)
    thick = max(1, round(2 * scale))
    for det in detections:
        colour = (60, 200, 60) if det.result.ok else (40, 40, 230)
        if det.corners is not None:
            cv2.polylines(out, [np.round(det.corners).astype(np.int32)], True, colour, thick, cv2.LINE_AA)
        for name, (x, y) in det.keypoints.items():
            cv2.circle(out, (round(x), round(y)), max(2, thick + 1), (0, 220, 255) if name != "centre" else colour, -1)
        if det.pose is not None:
            axes = np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0], [0, 0, -0.5]], dtype=np.float64)
            p = np.round(det.pose.project(axes)).astype(int)
            if np.abs(p).max() < 1e6:
                for end, c in ((1, (0, 0, 255)), (2, (0, 255, 0)), (3, (255, 0, 0))):
                    cv2.arrowedLine(out, tuple(p[0]), tuple(p[end]), c, thick, cv2.LINE_AA, tipLength=0.15)
        label = f"{format_payload(det.result.payload)['hex']} {'ok' if det.result.ok else '?'}"
        anchor = det.corners.min(0) if det.corners is not None else np.array([4.0, 20.0])
        org = (int(max(2, anchor[0])), int(max(14 * scale, anchor[1] - 6)))
        cv2.putText(out, label, org, cv2.FONT_HERSHEY_SIMPLEX, 0.55 * scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
        cv2.putText(out, label, org, cv2.FONT_HERSHEY_SIMPLEX, 0.55 * scale, colour, thick, cv2.LINE_AA)
    return out


__all__ = ["draw_overlay"]
