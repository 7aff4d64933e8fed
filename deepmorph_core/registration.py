"""Framed renders registered onto the unmorphed drawing, as the photo chain's first look sees them.

The photo chain aligns a photo to the *unmorphed* drawing (:mod:`deepmorph_detect.refine`) and
reads the view that alignment rectifies. A morph moves the drawing's ink, and the homography
that best fits the unmorphed drawing to it takes up part of that move: on close-ups of the
ghost it leaves the view a median 1.3 px rms off in the decoder's 96-px frame (after the shift
and scale that framing by ink removes), where the alignment to the print's own morph leaves
0.05 px. That part is no random misalignment: it is a function of the code. A model trained for
prints read at their own resolution (``train --pixels``) learns to read the view as the chain
makes it: each training render is registered onto the unmorphed drawing the same way, and the
random misalignment left for the corruption is only the alignment's own error
(:data:`~deepmorph_core.severity.REGISTERED_ALIGNMENT`). ``docs/design-notes.md`` has the
measurements.

The registration is inverse-compositional Lucas-Kanade over the same eight homography
parameters as the chain's ECC (:func:`motion_images`), on both images
blurred by :data:`BLUR_SIGMA` px, batched, the images warped in float32 and each step's 8x8 solve
in float64: the template's Jacobian and Hessian are computed once, and the steps stop once they
settle (:data:`SETTLED`). Registering 32 renders of ``cloud-snow`` and the gradient back
through the view take 15-25 ms on 2 threads. On resvg renders of ``battery-charging`` its views
differ from the chain's ECC views by 0.018 mean absolute gray, where the chain's own view at the
true homography differs by 0.017 (resampling alone) and the unregistered render by 0.032.
kornia's :class:`~kornia.geometry.transform.ImageRegistrator` fits one homography per call by
gradient descent: on the ghost seen through a 2-degree turn, shear and tilt it took 3.1 s and
left the view 0.043 mean gray from the drawing, this Gauss-Newton 13 ms and 0.024 (1 thread). So
this is written here, from kornia's blur and a warp of its own (:func:`sampling_grid`).
"""

from __future__ import annotations

import functools

import numpy as np
import torch
from kornia.filters import gaussian_blur2d
from torch import Tensor, nn
from torch.nn import functional as F

from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, to_channel

#: Blur (px of the decoder's frame) of both images before they are compared: the basin of a
#: morph's few-pixel moves, as the chain's coarse 48-px level gives its ECC.
BLUR_SIGMA = 1.0
#: Gauss-Newton steps at most; the views settle within the resampling noise by about six.
ITERATIONS = 8
#: ... and an image takes none more once no parameter of its step moves this much (unit
#: coordinates: 0.005 px of the 96-px frame): later steps of renders of four icons moved 0.0005 px
#: or less.
SETTLED = 1e-4


def _blurred(images: Tensor) -> Tensor:
    radius = max(1, int(3 * BLUR_SIGMA + 0.5))
    return gaussian_blur2d(images, (2 * radius + 1,) * 2, (BLUR_SIGMA, BLUR_SIGMA), border_type="replicate")


def motion_images(image: np.ndarray) -> np.ndarray:
    """``(8, h, w)`` how ``image`` (``(h, w)``) changes with each of the eight parameters of a
    small homography composed on the frame's side, in frame coordinates scaled to [-1, 1]:
    the Jacobian of an alignment solve, and what the per-bit check projects out as motion."""
    h, w = image.shape
    gy, gx = np.gradient(np.asarray(image, dtype=np.float64))
    gx *= max(w - 1, 1) / 2.0
    gy *= max(h - 1, 1) / 2.0
    x, y = _frame_coordinates(h, w)
    return homography_rows(gx, gy, x, y)


def homography_rows(gx: np.ndarray, gy: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``(8, *gx.shape)`` (in ``gx``'s dtype) the change of a picture with each of the eight
    parameters of a small homography, in the order :func:`_homography` and the alignment solvers
    compose them: the picture's gradients ``gx``, ``gy`` times each parameter's flow at the
    points ``x``, ``y`` (broadcast against the gradients)."""
    out = np.empty((8, *gx.shape), dtype=gx.dtype)
    np.multiply(gx, x, out=out[0])
    np.multiply(gx, y, out=out[1])
    out[2] = gx
    np.multiply(gy, x, out=out[3])
    np.multiply(gy, y, out=out[4])
    out[5] = gy
    radial = out[0] + out[4]  # gx * x + gy * y
    np.negative(radial, out=radial)
    np.multiply(radial, x, out=out[6])
    np.multiply(radial, y, out=out[7])
    return out


@functools.lru_cache(maxsize=16)
def _frame_coordinates(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """``(1, w)`` x and ``(h, 1)`` y of an ``(h, w)`` frame's pixels, scaled to [-1, 1]
    (read-only: every alignment step of that size shares them)."""
    x = 2.0 * np.arange(w, dtype=np.float64)[None] / max(w - 1, 1) - 1.0
    y = 2.0 * np.arange(h, dtype=np.float64)[:, None] / max(h - 1, 1) - 1.0
    x.flags.writeable = False
    y.flags.writeable = False
    return x, y


def _homography(params: Tensor) -> Tensor:
    """``(B, 8)`` parameters -> ``(B, 3, 3)``: the identity plus them, in the order of
    :func:`motion_images`."""
    one = torch.ones_like(params[:, :1])
    flat = torch.cat([params[:, :3], params[:, 3:6], params[:, 6:8], one], 1)
    return flat.view(-1, 3, 3) + torch.diag(params.new_tensor([1.0, 1.0, 0.0]))


def sampling_grid(homographies: Tensor, height: int, width: int) -> Tensor:
    """``(B, H, W, 2)``: where ``homographies`` ``(B, 3, 3)`` take each point of a ``height`` x
    ``width`` frame, in unit coordinates (the corner pixels' centres at -1 and 1), as
    :func:`~torch.nn.functional.grid_sample` reads them with ``align_corners=True``, in the
    homographies' dtype. Each coordinate is three broadcast multiply-adds of the frame's x and y:
    kornia's ``homography_warp`` builds the same grid as a batched matrix product with an inner
    dimension of 3, which MKL runs slowly: a registration's forward and backward of 32 96-px
    renders took 1.8-2.3x as long with it (2 threads), for views within 2e-5 gray of these."""
    rows = homographies.reshape(-1, 9, 1, 1)
    x = torch.linspace(-1.0, 1.0, width, dtype=rows.dtype, device=rows.device).view(1, 1, width)
    y = torch.linspace(-1.0, 1.0, height, dtype=rows.dtype, device=rows.device).view(1, height, 1)
    u = rows[:, 0] * x + rows[:, 1] * y + rows[:, 2]
    v = rows[:, 3] * x + rows[:, 4] * y + rows[:, 5]
    z = rows[:, 6] * x + rows[:, 7] * y + rows[:, 8]
    # a point sent to infinity stays where it is (kornia's rule)
    scale = torch.where(z.abs() > 1e-8, 1.0 / z, torch.ones_like(z))
    return torch.stack([u * scale, v * scale], -1)


def warp(images: Tensor, homographies: Tensor) -> Tensor:
    """``(B, C, H, W)`` images sampled at ``homographies`` ``(B, 3, 3)`` of each frame point (unit
    coordinates), bilinear: the view a rectification by that homography makes. Differentiable in
    ``images``; the nearest edge pixel (paper, in a framed render) where it looks outside."""
    grid = sampling_grid(homographies.to(images.dtype), *images.shape[-2:])
    return F.grid_sample(images, grid, mode="bilinear", padding_mode="border", align_corners=True)


class UnmorphedRegistration(nn.Module):
    """Registers framed renders onto the framed unmorphed drawing (``template``, ``(1, C, H, W)``
    gray or RGB, paper white = 1), both compared in the gray of ``channel`` (the one the
    photo chain aligns a model's colour photos in)."""

    def __init__(self, template: Tensor, channel: Channel = LUMA_WEIGHTS) -> None:
        super().__init__()
        self.channel = channel
        t = _blurred(to_channel(template[:1], channel).double())[0, 0]
        steepest = torch.from_numpy(motion_images(t.cpu().numpy()).reshape(8, -1)).to(t.device)
        self.register_buffer("template", t.reshape(-1).float())
        self.register_buffer("steepest", steepest.float())
        self.register_buffer("inverse_hessian", torch.linalg.inv(steepest @ steepest.T))

    def homographies(self, images: Tensor) -> Tensor:
        """``(B, 3, 3)`` float64: where each frame point of the unmorphed drawing lies in each image
        (unit coordinates). No gradient: the registration is the chain's, not something learnt."""
        with torch.no_grad():
            seen = _blurred(to_channel(images, self.channel).float())
            H = torch.eye(3, dtype=torch.float64, device=images.device).repeat(images.shape[0], 1, 1)
            moving = torch.arange(images.shape[0], device=images.device)
            for _ in range(ITERATIONS):
                current = H[moving]
                error = warp(seen[moving], current).flatten(1) - self.template
                step = (error @ self.steepest.T).double() @ self.inverse_hessian.T
                moved = current @ torch.linalg.inv(_homography(step))
                H[moving] = moved / moved[:, 2:3, 2:3]
                # each image stops once its own step settles: its homography is the one it gets alone
                moving = moving[step.abs().amax(1) >= SETTLED]
                if not len(moving):
                    break
            return H

    def forward(self, images: Tensor) -> Tensor:
        """``(B, C, H, W)`` -> the same images as the registration rectifies them."""
        return warp(images, self.homographies(images))


__all__ = [
    "BLUR_SIGMA",
    "ITERATIONS",
    "SETTLED",
    "UnmorphedRegistration",
    "homography_rows",
    "motion_images",
    "sampling_grid",
    "warp",
]
