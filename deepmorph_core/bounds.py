"""Bound-specs: what an artist allows to morph, read from ``dm:`` attributes and validated.

Attributes live in the namespace ``urn:deepmorph:1`` (prefix ``dm``) on any primitive or
``<g>``; on the root ``<svg>`` they are defaults for every primitive below that has none of
its own. See ``docs/bounds.md`` for the reference.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from deepmorph_core.svg.values import parse_numbers

ATTRIBUTES = ("move", "shift", "scale", "rotate", "fixed")


class BoundSpec(BaseModel):
    """Bounds on one element or group (every field optional; ``None`` means "not said here").

    Attributes:
        move: each control point may move within this radius (user units).
        shift: the element/group may translate by up to +-x and +-y (user units).
        scale: uniform scale range about the centre, ``lo <= hi``, both positive.
        rotate: rotation range in degrees about the centre, within [-180, 180].
        fixed: never morphs (nor does anything inside a fixed group).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    move: float | None = Field(default=None, ge=0.0, le=1e4)
    shift: tuple[float, float] | None = None
    scale: tuple[float, float] | None = None
    rotate: tuple[float, float] | None = None
    fixed: bool | None = None

    @field_validator("move", mode="before")
    @classmethod
    def _move(cls, v: Any) -> Any:
        if isinstance(v, str):
            nums = parse_numbers(v)
            if len(nums) != 1:
                raise ValueError('takes one radius, e.g. dm:move="0.5"')
            return nums[0]
        return v

    @field_validator("shift", mode="before")
    @classmethod
    def _shift(cls, v: Any) -> Any:
        if isinstance(v, str):
            nums = parse_numbers(v)
            if len(nums) not in (1, 2):
                raise ValueError('takes R or "RX RY"')
            v = (nums[0], nums[-1])
        if isinstance(v, (int, float)):
            v = (float(v), float(v))
        if v is not None and (min(v) < 0 or max(v) > 1e4):
            raise ValueError("radii must be between 0 and 10000")
        return v

    @field_validator("scale", "rotate", mode="before")
    @classmethod
    def _range(cls, v: Any) -> Any:
        if isinstance(v, str):
            nums = parse_numbers(v)
            if len(nums) != 2:
                raise ValueError('takes two numbers "LO HI"')
            return tuple(nums)
        return v

    @field_validator("fixed", mode="before")
    @classmethod
    def _fixed(cls, v: Any) -> Any:
        if isinstance(v, str):
            if v.strip().lower() not in ("true", "false"):
                raise ValueError('is "true" or "false"')
            return v.strip().lower() == "true"
        return v

    @model_validator(mode="after")
    def _ordered(self) -> BoundSpec:
        if self.scale is not None:
            lo, hi = self.scale
            if lo <= 0 or hi > 100:
                raise ValueError(f"scale: bounds must lie in (0, 100], got {lo:g} {hi:g}")
            if lo > hi:
                raise ValueError(f"scale: lower bound {lo:g} is above upper bound {hi:g}")
        if self.rotate is not None:
            lo, hi = self.rotate
            if lo < -180 or hi > 180:
                raise ValueError(f"rotate: degrees must lie in [-180, 180], got {lo:g} {hi:g}")
            if lo > hi:
                raise ValueError(f"rotate: lower bound {lo:g} is above upper bound {hi:g}")
        return self

    def over(self, fallback: BoundSpec) -> BoundSpec:
        """These bounds, with fields not said here taken from ``fallback``."""
        mine = self.model_dump(exclude_none=True)
        return BoundSpec(**{**fallback.model_dump(exclude_none=True), **mine})

    @property
    def is_empty(self) -> bool:
        return not self.model_dump(exclude_none=True)


def format_validation_error(
    exc: ValidationError, prefix: str = "dm:", known: Iterable[str] | None = ATTRIBUTES, kind: str = "attribute"
) -> str:
    """One readable ``{prefix}field: problem`` line per problem (``dm:move: ...`` for bounds);
    an unknown field is named as an unknown ``kind``, with the ``known`` ones where given."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(x) for x in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            listed = f" (known: {', '.join(prefix + a for a in known)})" if known is not None else ""
            lines.append(f"unknown {kind} {prefix}{loc}{listed}")
        elif loc:
            lines.append(f"{prefix}{loc}: {msg}")
        else:
            lines.append(msg)
    return "; ".join(lines)


def parse_bounds(attributes: dict[str, str]) -> BoundSpec:
    """Validate the ``dm:`` attributes of one element (local names to raw strings).

    Raises:
        ValueError: with a readable message (the caller adds file and line).
    """
    try:
        return BoundSpec(**attributes)
    except ValidationError as exc:
        raise ValueError(format_validation_error(exc)) from None
