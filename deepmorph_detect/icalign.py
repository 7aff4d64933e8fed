"""ECC alignment by inverse composition: the same criterion as OpenCV's ``findTransformECC``,
about three times faster for the solves that start close to the answer.

OpenCV's ECC is forward-additive: every iteration it warps the photo *and its two gradient
images*, builds the eight Jacobian images and the 8x8 Hessian afresh, some sixty passes over
the pixels. The inverse-compositional form (Baker and Matthews; Evangelidis and Psarakis give
the ECC variant) linearises the *template* instead. Its steepest-descent images and Hessian
depend on the template alone and are made once per template (:class:`InverseECC`); an
iteration then warps the photo once and takes eight dot products. The ECC correction for
contrast and brightness (the scalar lambda) is kept, so the criterion, the zero-mean
normalised correlation, is the same.

Where it is used: the finer levels of :func:`~deepmorph_detect.refine.refine` and the
one-level refits (:func:`~deepmorph_detect.refine.refine_at`), which start within a pixel or
two of the answer; there it reaches the same correlation as OpenCV. At the coarsest level,
which starts from the detector's rough outline, a linearisation at the template has the
narrower basin, so a coarse solve that ends below a bar is done again by OpenCV's
forward-additive ECC (:func:`~deepmorph_detect.refine._coarse_steps`).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from deepmorph_core.registration import homography_rows


@functools.lru_cache(maxsize=16)
def _unit_coordinates(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel x and y of an ``(h, w)`` image, raveled, centred and scaled to about [-1, 1]
    (read-only: shared by every solver of that size)."""
    s = max(w, h) / 2.0
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    x = ((xs - (w - 1) / 2.0) / s).ravel()
    y = ((ys - (h - 1) / 2.0) / s).ravel()
    x.flags.writeable = False
    y.flags.writeable = False
    return x, y


def inverse3(m: np.ndarray) -> np.ndarray:
    """The inverse of a ``(3, 3)`` matrix by its adjugate: what ``np.linalg.inv`` gives (to
    float rounding) in a tenth of the time, for the solve's per-iteration updates.

    Raises:
        np.linalg.LinAlgError: ``m`` is singular (or not finite).
    """
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    co_a, co_b, co_c = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * co_a + b * co_b + c * co_c
    if det == 0.0 or not math.isfinite(det):
        raise np.linalg.LinAlgError("singular matrix")
    r = 1.0 / det
    return np.array(
        [
            [co_a * r, (c * h - b * i) * r, (b * f - c * e) * r],
            [co_b * r, (a * i - c * g) * r, (c * d - a * f) * r],
            [co_c * r, (b * g - a * h) * r, (a * e - b * d) * r],
        ]
    )


class InverseECC:
    """The ECC alignment of photos to one template image, with the template's side precomputed.

    Args:
        template: ``(h, w)`` float32 template (1 = white).
        smooth: Gaussian kernel size applied to the template and to each photo crop, as
            ``findTransformECC``'s ``gaussFiltSize``.
    """

    def __init__(self, template: np.ndarray, smooth: int) -> None:
        t = cv2.GaussianBlur(np.asarray(template, dtype=np.float32), (smooth, smooth), 0)
        h, w = t.shape
        self.shape = (h, w)
        self.smooth = smooth
        # homography parameters live in centred coordinates scaled to about [-1, 1], so that
        # the eight columns of the Hessian have comparable sizes
        s = max(w, h) / 2.0
        cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
        self._to_unit = np.array([[1 / s, 0, -cx / s], [0, 1 / s, -cy / s], [0, 0, 1]])
        self._from_unit = inverse3(self._to_unit)
        gx = (cv2.Sobel(t, cv2.CV_32F, 1, 0, ksize=1) * np.float32(0.5 * s)).ravel()
        gy = (cv2.Sobel(t, cv2.CV_32F, 0, 1, ksize=1) * np.float32(0.5 * s)).ravel()
        x, y = _unit_coordinates(h, w)
        # d(template)/d(parameters) at the identity warp, one row per parameter
        steepest = homography_rows(gx, gy, x, y)
        self._steepest = steepest
        zero_mean = (t - t.mean()).ravel()
        self._template = zero_mean
        zm64 = zero_mean.astype(np.float64)
        self._template_norm2 = float(zm64 @ zm64)
        # products in single precision (each a sum of h * w terms of one sign pattern; their
        # relative error, about 1e-6, is far below what the solve resolves), inverted in double
        self._hessian_inv = np.linalg.inv((steepest @ steepest.T).astype(np.float64))
        self._template_proj = (steepest @ zero_mean).astype(np.float64)
        self._template_proj_h = self._hessian_inv @ self._template_proj
        self._lambda_num = self._template_norm2 - float(self._template_proj @ self._template_proj_h)

    def _correlation(self, img: np.ndarray, warp: np.ndarray) -> tuple[float, float, np.ndarray]:
        """The zero-mean normalised correlation of the template with ``img`` warped by
        ``warp`` (template px -> img px), the dot product behind it, and the warped pixels."""
        h, w = self.shape
        warped = cv2.warpPerspective(
            img, warp, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE
        ).ravel()
        warped -= cv2.mean(warped)[0]  # OpenCV's mean: the same (summed in double) in half numpy's time
        dot = float(self._template @ warped)
        den = float(np.sqrt(float(warped @ warped) * self._template_norm2))
        return (dot / den if den > 1e-12 else 0.0), dot, warped

    def align(self, crop: np.ndarray, iterations: int, eps: float) -> tuple[float, np.ndarray] | None:
        """The warp (template px -> ``crop`` px, from the identity) that maximises the
        correlation, and that correlation; ``None`` when the solve breaks down (the photo does
        not correlate with the template at all, or the warp degenerates).

        Stops after ``iterations`` updates or when the correlation gains less than ``eps``;
        returns the best warp met, so it never ends worse than it started.
        """
        img = cv2.GaussianBlur(crop, (self.smooth, self.smooth), 0)
        unit = np.eye(3)
        best: tuple[float, np.ndarray] | None = None
        for step in range(iterations + 1):
            warp = self._from_unit @ unit @ self._to_unit
            rho, dot, warped = self._correlation(img, warp)
            if best is not None and rho <= best[0]:
                break  # the last update overshot: keep the best
            gain = rho - best[0] if best is not None else np.inf
            best = (rho, warp)
            if gain < eps or step == iterations:
                break
            proj = self._steepest @ warped
            # ECC's contrast correction: the photo's scale that the template's update must match
            lambda_den = dot - float(proj @ self._template_proj_h)
            if lambda_den <= 0.0:
                return None if step == 0 else best
            scale = self._lambda_num / lambda_den
            delta = self._hessian_inv @ (scale * proj.astype(np.float64) - self._template_proj)
            update = np.array(
                [[1 + delta[0], delta[1], delta[2]], [delta[3], 1 + delta[4], delta[5]], [delta[6], delta[7], 1.0]]
            )
            try:
                unit = unit @ inverse3(update)
            except np.linalg.LinAlgError:
                break
            if not math.isfinite(float(unit.sum())) or abs(unit[2, 2]) < 1e-9:  # the sum carries any NaN or inf
                break
            unit = unit / unit[2, 2]
        return best


__all__ = ["InverseECC", "inverse3"]
