"""The morph space of a drawing: its variables, their bounds, the map T, and perturbation.

Variables come in blocks:

* per-point moves: two variables per control point, mapped onto a disk of radius ``dm:move``
  (a smooth square-to-disk map, so every value of the encoder's sigmoid lands inside), shrunk
  per point so that no ink moves further than ``dm:move`` (:func:`ink_reach`, geometry 2);
* element- and group-level affines: shift x/y (within +-R), scale and rotation (within
  ``[lo, hi]``), about the element's or group's centre.

``T`` maps the encoder's ``(0, 1)`` outputs onto these bounds; :meth:`MorphSpace.frames`
turns values into batched pixel-space frames for the rasterizer; :meth:`MorphSpace.write_svg`
writes one morph back into SVG.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from lxml import etree
from torch import Tensor

from deepmorph_core.drawing import Drawing
from deepmorph_core.outline import Frame
from deepmorph_core.primitive import append_transform
from deepmorph_core.protocols import ElementMorph
from deepmorph_core.svg.values import format_matrix


@dataclass(frozen=True)
class Variable:
    """One morph variable.

    Attributes:
        owner: ``"primitive"`` or ``"group"``.
        index: index of the owning primitive or group.
        role: ``move-x``, ``move-y``, ``shift-x``, ``shift-y``, ``scale`` or ``rotate``.
        point: control point index for moves, else -1.
        lo, hi: bounds in physical units (user units, scale factor, degrees). Move bounds are
            the disk's radius: the pair (x, y) always lies within it.
        line: source line of the owning element.
    """

    owner: str
    index: int
    role: str
    point: int
    lo: float
    hi: float
    line: int | None


_AFFINE_ROLES = ("shift-x", "shift-y", "scale", "rotate")


def ink_reach(primitive: object, n_points: int) -> np.ndarray:
    """``(n,)`` how far a primitive's ink can move, at most, per unit move of each control point
    (every point moving within the same radius): 1 where the ink moves no further than the points
    (lines, polygons, Bezier curves, which stay in the hull of their points), more where it
    swings further (an arc's bulge). A point's move radius is the artist's ``dm:move`` divided by
    this, so that the bound holds in the ink. Primitives say so through an optional
    ``ink_reach()`` method; without one, 1."""
    method = getattr(primitive, "ink_reach", None)
    if method is None:
        return np.ones(n_points)
    reach = np.asarray(method(), dtype=np.float64).reshape(-1)
    if reach.shape != (n_points,) or not np.isfinite(reach).all() or (reach < 1.0 - 1e-9).any():
        raise ValueError(f"{type(primitive).__name__}.ink_reach() must give {n_points} factors >= 1, got {reach}")
    return reach


class MorphSpace:
    """Variables and bounds of a drawing, and the differentiable map from values to geometry.

    Args:
        drawing: the parsed drawing.
    """

    def __init__(self, drawing: Drawing):
        self.drawing = drawing
        self.variables: list[Variable] = []
        self._prim_moves: list[np.ndarray] = []  # (n, 2) indices into padded values (N = none)
        self._prim_affine: list[np.ndarray] = []  # (4,) shift-x, shift-y, scale, rotate
        self._group_affine: list[np.ndarray] = []
        for group in drawing.groups:
            self._group_affine.append(self._affine_vars("group", group.index, group.bounds, group.line))
        for prim in drawing.primitives:
            n = prim.primitive.control_points().shape[0]
            moves = np.full((n, 2), -1, dtype=np.int64)
            if not prim.fixed:
                radius = prim.bounds.move or 0.0
                if radius > 0:
                    reach = ink_reach(prim.primitive, n) if drawing.geometry >= 2 else np.ones(n)
                    for k in range(n):
                        r = radius / reach[k]
                        for axis, role in enumerate(("move-x", "move-y")):
                            moves[k, axis] = self._add(Variable("primitive", prim.index, role, k, -r, r, prim.line))
            self._prim_moves.append(moves)
            affine = (
                np.full(4, -1, dtype=np.int64)
                if prim.fixed
                else self._affine_vars("primitive", prim.index, prim.bounds, prim.line)
            )
            self._prim_affine.append(affine)
        nv = len(self.variables)
        lo = torch.tensor([v.lo for v in self.variables], dtype=torch.float64)
        hi = torch.tensor([v.hi for v in self.variables], dtype=torch.float64)
        self.lower, self.upper = lo, hi
        # scale variables are stored as (factor - 1) so that a missing variable (0) is neutral
        self._offset = torch.tensor([1.0 if v.role == "scale" else 0.0 for v in self.variables], dtype=torch.float64)
        pairs = [
            (self._prim_moves[p][k, 0], self._prim_moves[p][k, 1])
            for p in range(len(self._prim_moves))
            for k in range(self._prim_moves[p].shape[0])
            if self._prim_moves[p][k, 0] >= 0
        ]
        self._move_pairs = torch.tensor(pairs, dtype=torch.long).reshape(-1, 2)
        self._points_cache: dict[tuple[int, torch.dtype, torch.device], Tensor] = {}
        self._points_np: dict[int, np.ndarray] = {}
        self._fix_none(nv)

    # -- construction ---------------------------------------------------------------------

    def _add(self, var: Variable) -> int:
        self.variables.append(var)
        return len(self.variables) - 1

    def _affine_vars(self, owner: str, index: int, bounds, line: int | None) -> np.ndarray:
        idx = np.full(4, -1, dtype=np.int64)
        if bounds.shift is not None:
            for axis, role in enumerate(("shift-x", "shift-y")):
                r = bounds.shift[axis]
                if r > 0:
                    idx[axis] = self._add(Variable(owner, index, role, -1, -r, r, line))
        if bounds.scale is not None and bounds.scale[0] < bounds.scale[1]:
            idx[2] = self._add(Variable(owner, index, "scale", -1, bounds.scale[0], bounds.scale[1], line))
        if bounds.rotate is not None and bounds.rotate[0] < bounds.rotate[1]:
            idx[3] = self._add(Variable(owner, index, "rotate", -1, bounds.rotate[0], bounds.rotate[1], line))
        return idx

    def _fix_none(self, nv: int) -> None:
        """Point "no variable" (-1) at the zero column appended to values at run time."""
        for arr in (*self._prim_moves, *self._prim_affine, *self._group_affine):
            arr[arr < 0] = nv
        self._moves_t = [torch.from_numpy(a) for a in self._prim_moves]
        self._prim_affine_t = [torch.from_numpy(a) for a in self._prim_affine]
        self._group_affine_t = [torch.from_numpy(a) for a in self._group_affine]

    # -- the map T ----------------------------------------------------------------------

    @property
    def n_variables(self) -> int:
        """``N_v``, the number of morph variables."""
        return len(self.variables)

    def values_from_unit(self, unit: Tensor) -> Tensor:
        """Map encoder outputs in ``[0, 1]`` onto the bounds (the paper's ``T``).

        Move pairs go through the square-to-disk map ``(x sqrt(1 - y^2/2), y sqrt(1 - x^2/2))``,
        so a point never leaves its disk. Scale values come out as ``factor - 1``.

        Shape:
            ``(B, N_v)`` -> ``(B, N_v)``.
        """
        if unit.shape[-1] != self.n_variables:
            raise ValueError(f"expected {self.n_variables} variables, got shape {tuple(unit.shape)}")
        lo = self.lower.to(unit)
        hi = self.upper.to(unit)
        values = lo + (hi - lo) * unit
        if self._move_pairs.numel():
            pairs = self._move_pairs.to(unit.device)
            ix, iy = pairs[:, 0], pairs[:, 1]
            r = hi[ix]
            x, y = values[:, ix] / r, values[:, iy] / r
            dx = r * x * torch.sqrt((1 - y * y / 2).clamp_min(0))
            dy = r * y * torch.sqrt((1 - x * x / 2).clamp_min(0))
            values = values.index_copy(1, ix, dx).index_copy(1, iy, dy)
        return values - self._offset.to(unit)

    def values_from_unit_one(self, unit: np.ndarray) -> np.ndarray:
        """:meth:`values_from_unit` of one ``(N_v,)`` row, in numpy float64: the same numbers
        (to float rounding) without a dozen torch operations on a few dozen values, which the
        photo chain would pay for every payload it checks (about 3 % of a frame's time)."""
        unit = np.asarray(unit, dtype=np.float64).reshape(-1)
        if unit.shape[0] != self.n_variables:
            raise ValueError(f"expected {self.n_variables} variables, got shape {unit.shape}")
        lo, hi = self.lower.numpy(), self.upper.numpy()  # float64 views of the bounds
        values = lo + (hi - lo) * unit
        pairs = self._move_pairs.numpy()
        if len(pairs):
            ix, iy = pairs[:, 0], pairs[:, 1]
            r = hi[ix]
            x, y = values[ix] / r, values[iy] / r
            values[ix] = r * x * np.sqrt(np.maximum(1 - y * y / 2, 0.0))
            values[iy] = r * y * np.sqrt(np.maximum(1 - x * x / 2, 0.0))
        return values - self._offset.numpy()

    def neutral_unit(self, batch: int = 1, dtype: torch.dtype = torch.float32) -> Tensor:
        """Encoder outputs closest to "no morph" (0.5 for symmetric bounds).

        Shape:
            -> ``(batch, N_v)``.
        """
        lo, hi = self.lower, self.upper
        neutral = self._offset  # 1 for scale, 0 otherwise
        u = ((neutral - lo) / (hi - lo)).clamp(0, 1)
        return u.to(dtype).expand(batch, -1).clone()

    def physical(self, values: Tensor) -> Tensor:
        """Values in the units users read (scale as a factor)."""
        return values + self._offset.to(values)

    # -- geometry -------------------------------------------------------------------------

    def frames(self, values: Tensor, width: int) -> list[Frame]:
        """Pixel-space frames of every primitive for a batch of morph values.

        Args:
            values: ``(B, N_v)`` from :meth:`values_from_unit` (``B`` perturbations).
            width: raster width in pixels.

        Returns:
            One :class:`Frame` per primitive, in document order.
        """
        B = values.shape[0]
        dtype, device = values.dtype, values.device
        ext = torch.cat([values, values.new_zeros(B, 1)], 1)
        pix = torch.as_tensor(self.drawing.pixel_matrix(width), dtype=dtype, device=device)
        group_world = []
        for group, idx in zip(self.drawing.groups, self._group_affine_t):
            g = torch.as_tensor(group.ctm, dtype=dtype, device=device)
            m = _affine(ext[:, idx.to(device)], group.centre)
            group_world.append(g @ m @ torch.linalg.inv(g))
        prims = self.drawing.primitives
        if not prims:
            return []
        # All element-level affines in one batched call: (B, n_prims, 3, 3).
        aff_idx = torch.stack(self._prim_affine_t).to(device)  # (n_prims, 4)
        centres = torch.as_tensor(np.stack([p.centre for p in prims]), dtype=dtype, device=device)
        element = _affine(ext[:, aff_idx], centres)
        static = pix @ torch.as_tensor(np.stack([p.ctm for p in prims]), dtype=dtype, device=device)  # (n, 3, 3)
        static = static.expand(B, -1, -1, -1)
        if group_world:  # group morphs sit between the viewBox scale and each element's CTM
            static = static.clone()
            for i, prim in enumerate(prims):
                if prim.groups:
                    a = pix.expand(B, 3, 3)
                    for gi in prim.groups:
                        a = a @ group_world[gi]
                    static[:, i] = a @ torch.as_tensor(prim.ctm, dtype=dtype, device=device)
        stroke_scale = torch.sqrt(torch.linalg.det(static[..., :2, :2]).abs())  # (B, n)
        full = static @ element
        out = []
        for i, moves in enumerate(self._moves_t):
            local = self._base_points(i, dtype, device)[None] + ext[:, moves.to(device)]
            out.append(Frame(local, full[:, i], stroke_scale[:, i]))
        return out

    def _base_points(self, index: int, dtype: torch.dtype, device: torch.device) -> Tensor:
        """A primitive's unmorphed control points, converted once per dtype and device."""
        key = (index, dtype, device)
        cached = self._points_cache.get(key)
        if cached is None:
            cached = self.drawing.primitives[index].primitive.control_points().to(dtype=dtype, device=device)
            self._points_cache[key] = cached
        return cached

    def _base_points_np(self, index: int) -> np.ndarray:
        """A primitive's unmorphed control points as float64 NumPy, made once: decoding a photo
        writes a morph per payload read, and rebuilding them each time costs a fifth of that."""
        points = self._points_np.get(index)
        if points is None:
            points = self._points_np[index] = self._base_points(index, torch.float64, torch.device("cpu")).numpy()
        return points

    # -- writing back ---------------------------------------------------------------------

    def write_svg(self, values: Tensor) -> str:
        """The drawing with one morph baked in, as SVG text holding only what DeepMorph models
        (:meth:`Drawing.sanitized <deepmorph_core.drawing.Drawing.sanitized>`).

        Args:
            values: ``(N_v,)`` or ``(1, N_v)`` morph values (from :meth:`values_from_unit`).
        """
        return self.write_svgs(values.detach().reshape(1, -1))[0]

    def write_svgs(self, values: Tensor) -> list[str]:
        """:meth:`write_svg` of each of ``(B, N_v)`` morphs, the same texts: the drawing is
        sanitized once and each morph written into that one copy in turn (the checks draw ten
        one-bit variants of a word at a time, where copying and sanitizing the tree took a
        fifth of each)."""
        v = values.detach().to(torch.float64).cpu()
        if v.ndim != 2 or v.shape[1] != self.n_variables:
            raise ValueError(f"expected (B, {self.n_variables}) values, got {tuple(v.shape)}")
        copies: dict[etree._Element, etree._Element] = {}
        tree = self.drawing.sanitized(copies)
        elements = [group.element for group in self.drawing.groups] + [p.element for p in self.drawing.primitives]
        nodes = [copies[element] for element in elements if element in copies]
        unmorphed = [list(node.attrib.items()) for node in nodes]
        texts = []
        for row in torch.cat([v, v.new_zeros(len(v), 1)], dim=1).numpy():
            for node, attributes in zip(nodes, unmorphed):
                node.attrib.clear()
                for name, value in attributes:
                    node.set(name, value)
            self._write_morph(row, copies)
            texts.append(etree.tostring(tree, encoding="unicode"))
        return texts

    def _write_morph(self, ext: np.ndarray, copies: dict[etree._Element, etree._Element]) -> None:
        """Write the morph ``ext`` (values and a trailing 0 for "no variable") into the
        sanitized copies (``copies``: the drawing's elements to theirs) of its groups and
        primitives; one the sanitized tree left out (inside an element it drops) is not written."""
        for group, idx in zip(self.drawing.groups, self._group_affine):
            morph = _element_morph(ext[idx], group.centre)
            if not morph.is_identity and group.element in copies:
                append_transform(copies[group.element], format_matrix(morph.matrix()))
        for prim, moves, aff in zip(self.drawing.primitives, self._prim_moves, self._prim_affine):
            delta = ext[moves]
            morph = _element_morph(ext[aff], prim.centre)
            if (not delta.any() and morph.is_identity) or prim.element not in copies:
                continue
            points = self._base_points_np(prim.index) + delta
            prim.primitive.write(copies[prim.element], points, morph)


def _affine(params: Tensor, centre: np.ndarray | Tensor) -> Tensor:
    """Batched ``T(c + shift) R(rot) S(1 + s) T(-c)`` from ``(..., 4)`` [shift-x, shift-y, s, rot°]
    about ``centre`` (``(2,)``, or ``(..., 2)`` matching ``params``): ``(..., 3, 3)``."""
    if isinstance(centre, Tensor):
        cx, cy = centre[..., 0], centre[..., 1]
    else:
        cx, cy = float(centre[0]), float(centre[1])
    shx, shy, s, rot = params.unbind(-1)
    ang = torch.deg2rad(rot)
    c, sn = torch.cos(ang) * (1 + s), torch.sin(ang) * (1 + s)
    tx = cx + shx - (c * cx - sn * cy)
    ty = cy + shy - (sn * cx + c * cy)
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    return torch.stack(
        [torch.stack([c, -sn, tx], -1), torch.stack([sn, c, ty], -1), torch.stack([zero, zero, one], -1)], -2
    )


def _element_morph(params: np.ndarray, centre: np.ndarray) -> ElementMorph:
    shx, shy, s, rot = (float(x) for x in params)
    return ElementMorph((float(centre[0]), float(centre[1])), (shx, shy), 1.0 + s, rot)
