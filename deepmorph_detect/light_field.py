"""The light across a print as a coarse grid, and the print aligned in it: what a cast shadow
leaves to the morph check.

ECC (:mod:`~deepmorph_detect.refine`) matches the photo to the drawing up to one contrast and
one brightness for the whole print. A cast shadow darkens part of it, and ECC bends the
alignment towards the shadow's edge. Here the light is a contrast field and a brightness field,
each bilinear on a ``k x k`` grid of knots over the drawing's frame (:func:`grid_fields`): a
shadow's darkening, and its penumbra down to about a cell. :func:`align_in_light_field` fits
the homography and both fields together by Gauss-Newton, with Cauchy weights so that what no
cell follows (a sharp penumbra) counts little.

OpenCV's ``findTransformECC`` fits one contrast and brightness, and kornia's registration
(gradient descent on a photometric loss) none, which is why this solver is our own. Its normal
equations use the grid's separable structure (each knot's field is a hat in x times a hat in y):
a 128-px alignment takes about 45 ms on one thread, ECC's about 1 ms, so it runs only where ECC's
has failed: for a word the check has withdrawn, and for a print aligned well and not read
(:func:`realign_in_light_field`; ``docs/detection.md``).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from deepmorph_core.registration import motion_images
from deepmorph_detect.icalign import inverse3
from deepmorph_detect.refine import Alignment, ImagePyramid, Template, aligned_at, warp_to_template

LIGHT_GRID = 8  # knots across the frame (each way) of the alignment's light fields
ITERATIONS = 15  # Gauss-Newton updates at most
STEP_TOLERANCE = 2e-4  # ... stopping once no homography parameter moves more than this
ROBUST_SCALE = 2.0  # Cauchy weights' scale, in robust standard deviations of the residual
SMOOTHING = 1.0  # Gaussian sigma (px) applied to the template and to the photo before comparing
# damping of the normal equations, relative to the light's: a cell of bare paper cannot tell its
# contrast from its brightness
RIDGE = 1e-6


@functools.lru_cache(maxsize=32)
def hats(n: int, k: int) -> np.ndarray:
    """``(n, k)`` bilinear hat functions of ``k`` knots spread evenly over ``n`` pixels (the
    first at pixel 0, the last at ``n - 1``); ``k == 1``: a constant (read-only)."""
    if k == 1:
        out = np.ones((n, 1))
    else:
        u = np.linspace(0.0, k - 1.0, n)
        out = np.maximum(0.0, 1.0 - np.abs(u[:, None] - np.arange(k)[None, :]))
    out.flags.writeable = False
    return out


def grid_fields(h: int, w: int, k: int) -> np.ndarray:
    """``(h * w, k * k)`` the smooth fields of a ``k x k`` grid over an ``(h, w)`` image: each
    knot's bilinear hat (they add up to 1 everywhere)."""
    return np.einsum("ya,xb->yxab", hats(h, k), hats(w, k)).reshape(h * w, k * k)


def _project(images: np.ndarray, hy: np.ndarray, hx: np.ndarray) -> np.ndarray:
    """``(..., k * k)`` the sum of each of ``images`` (``(..., h, w)``) against each knot's field."""
    return (hy.T @ images @ hx).reshape(*images.shape[:-2], -1)


def _gram(image: np.ndarray, pairs_y: np.ndarray, pairs_x: np.ndarray) -> np.ndarray:
    """``(k * k, k * k)`` the sums of ``image`` (``(h, w)``) times each pair of knots' fields,
    from :func:`_pairs` of the hats each way."""
    k = math.isqrt(pairs_x.shape[1])
    summed = pairs_y.T @ (image @ pairs_x)  # ((a, c), (b, d))
    return summed.reshape(k, k, k, k).transpose(0, 2, 1, 3).reshape(k * k, k * k)


def _pairs(hats_1d: np.ndarray) -> np.ndarray:
    """``(n, k * k)`` the products of each pair of one direction's ``k`` hats (``(n, k)``)."""
    n, k = hats_1d.shape
    return (hats_1d[:, :, None] * hats_1d[:, None, :]).reshape(n, k * k)


def _smoothed(image: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(image.astype(np.float64), (0, 0), SMOOTHING)


def align_in_light_field(
    pyramid: ImagePyramid,
    homography: np.ndarray,
    template: Template,
    width: int,
    grid: int = LIGHT_GRID,
    iterations: int = ITERATIONS,
) -> Alignment | None:
    """The photo aligned to ``template`` at ``width`` (which it must hold) from ``homography``
    (SVG units -> image pixels), in a light of ``grid x grid`` contrast and brightness knots
    fitted with it: first in a grid half as fine (a fine light takes up part of a misalignment
    of a few pixels, and stops there), then in the whole grid, each for at most ``iterations``
    updates. The alignment's correlation is ECC's (zero-mean normalised, one light for the
    whole print) at the pose reached, so that it compares with ECC's bars. ``None`` when the
    solve breaks down."""
    H: np.ndarray | None = np.asarray(homography, np.float64)
    for knots in dict.fromkeys((max(2, grid // 2), grid)):
        H = _aligned(pyramid, H, template, width, knots, iterations)
        if H is None:
            return None
    return aligned_at(pyramid, H, template, width)


#: (template width, light grid) of :func:`realign_in_light_field`'s steps, coarse to fine: from a
#: first alignment bent by a shadow's edge, a fine light at once takes up the misalignment
REALIGN_STEPS = ((48, 3), (128, LIGHT_GRID))


def realign_in_light_field(pyramid: ImagePyramid, alignment: Alignment, template: Template) -> Alignment | None:
    """``alignment`` (the unmorphed drawing's) aligned again in a grid of light, coarse to fine
    (:data:`REALIGN_STEPS`); ``None`` when a solve breaks down."""
    for width, grid in REALIGN_STEPS:
        realigned = align_in_light_field(pyramid, alignment.homography, template, width, grid)
        if realigned is None:
            return None
        alignment = realigned
    return alignment


def _aligned(
    pyramid: ImagePyramid, homography: np.ndarray, template: Template, width: int, grid: int, iterations: int
) -> np.ndarray | None:
    """:func:`align_in_light_field`'s Gauss-Newton solve in one grid: the homography reached."""
    t = _smoothed(template.images[width])
    h, w = t.shape
    hy, hx = hats(h, grid), hats(w, grid)
    kk = grid * grid
    to_frame = np.array([[(w - 1) / 2.0, 0, (w - 1) / 2.0], [0, (h - 1) / 2.0, (h - 1) / 2.0], [0, 0, 1.0]])
    from_frame = inverse3(to_frame)
    to_svg = template.to_svg_units(width)
    from_svg = inverse3(to_svg)
    H = np.asarray(homography, np.float64)
    weights = np.ones((h, w))
    pairs_y, pairs_x = _pairs(hy), _pairs(hx)
    n = 8 + 2 * kk
    contrast_cols, brightness_cols = slice(8, 8 + kk), slice(8 + kk, n)
    for _ in range(iterations):
        photo = _smoothed(warp_to_template(pyramid, H, template, width))
        motion = motion_images(photo)
        # unknowns: 8 motion parameters, then the contrast knots, then the brightness knots;
        # residual = photo + motion . dp - (contrast * t + brightness), weighted
        normal = np.empty((n, n))
        rhs = np.empty(n)
        wm = motion * weights
        normal[:8, :8] = wm.reshape(8, -1) @ motion.reshape(8, -1).T
        rhs[:8] = -(wm.reshape(8, -1) @ photo.ravel())
        # the brightness field's light is 1 everywhere: its products are the contrast's without t
        normal[:8, contrast_cols] = -_project(wm * t, hy, hx)
        normal[:8, brightness_cols] = -_project(wm, hy, hx)
        normal[8:, :8] = normal[:8, 8:].T
        weighted_t = weights * t
        rhs[contrast_cols] = _project(weighted_t * photo, hy, hx)
        rhs[brightness_cols] = _project(weights * photo, hy, hx)
        normal[contrast_cols, contrast_cols] = _gram(weighted_t * t, pairs_y, pairs_x)
        cross = _gram(weighted_t, pairs_y, pairs_x)
        normal[brightness_cols, contrast_cols] = cross
        normal[contrast_cols, brightness_cols] = cross.T
        normal[brightness_cols, brightness_cols] = _gram(weights, pairs_y, pairs_x)
        normal[np.diag_indices(n)] += RIDGE * float(np.diagonal(normal)[8:].mean())
        try:
            solution = np.linalg.solve(normal, rhs)
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(solution).all():
            return None
        dp, contrast, brightness = solution[:8], solution[8 : 8 + kk], solution[8 + kk :]
        model = hy @ contrast.reshape(grid, grid) @ hx.T * t + hy @ brightness.reshape(grid, grid) @ hx.T
        residual = photo - model
        scale = ROBUST_SCALE * 1.4826 * float(np.median(np.abs(residual))) + 1e-6
        weights = 1.0 / (1.0 + (residual / scale) ** 2)
        step = np.array([[1 + dp[0], dp[1], dp[2]], [dp[3], 1 + dp[4], dp[5]], [dp[6], dp[7], 1.0]])
        try:
            H = H @ to_svg @ to_frame @ step @ from_frame @ from_svg
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(H).all() or abs(H[2, 2]) < 1e-12:
            return None
        H = H / H[2, 2]
        if float(np.abs(dp).max()) < STEP_TOLERANCE:
            break
    return H


__all__ = ["LIGHT_GRID", "REALIGN_STEPS", "align_in_light_field", "grid_fields", "hats", "realign_in_light_field"]
