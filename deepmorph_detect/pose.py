"""Where a decoded drawing is: its corners and keypoints in the photo, and the camera's pose.

The homography (SVG units -> image pixels) from alignment gives the corners of the drawing's
frame and a 3x3 grid of keypoints over it; PnP on that grid gives the camera pose in the
drawing's own frame (:mod:`deepmorph_detect.camera`).
"""

from __future__ import annotations

import numpy as np

from deepmorph_detect.camera import Camera, project, solve_pose, viewbox_corners, viewbox_to_frame
from deepmorph_detect.check import PayloadCheck
from deepmorph_detect.propose import quad_bbox
from deepmorph_detect.results import Located

KEYPOINT_NAMES = ("top_left", "top_right", "bottom_right", "bottom_left")
_GRID = np.array([[fx, fy] for fy in (0.0, 0.5, 1.0) for fx in (0.0, 0.5, 1.0)])  # PnP points, viewBox shares


class Placer:
    """Places decoded drawings of one viewBox in photos."""

    def __init__(self, viewbox: tuple[float, float, float, float]) -> None:
        self.viewbox = viewbox
        self.to_frame = viewbox_to_frame(viewbox)  # SVG units -> pose frame
        self.frame_corners = viewbox_corners(viewbox)

    def place(
        self,
        image_size: tuple[int, int],
        H: np.ndarray,
        checked: PayloadCheck,
        probs: np.ndarray,
        correlation: float,
        score: float,
        camera: Camera,
        source: str,
    ) -> Located:
        """A decoded drawing at homography ``H`` in an image of ``(height, width)``: its
        corners, keypoints and camera pose."""
        h, w = image_size
        corners = project(H, self.frame_corners)
        x, y, vw, vh = self.viewbox
        svg_pts = np.column_stack([x + _GRID[:, 0] * vw, y + _GRID[:, 1] * vh])
        img_pts = project(H, svg_pts)
        obj = project(self.to_frame, svg_pts)
        rvec, tvec = solve_pose(camera, np.column_stack([obj, np.zeros(len(obj))]), img_pts)
        keypoints = {n: [round(float(v), 2) for v in c] for n, c in zip(KEYPOINT_NAMES, corners)}
        keypoints["centre"] = [round(float(v), 2) for v in project(H, np.array([[x + vw / 2, y + vh / 2]]))[0]]
        return Located(
            checked.result,
            probs,
            quad_bbox(corners, w, h),
            corners=corners,
            homography=H,
            correlation=correlation,
            score=score,
            rvec=rvec,
            tvec=tvec,
            camera=camera,
            keypoints=keypoints,
            source=source,
            morph=checked.fit,
            bits=checked.bits,
            morph_check=checked.status,
        )


__all__ = ["KEYPOINT_NAMES", "Placer"]
