"""``POST /v1/points`` and ``POST /v1/points/inverse``: world points to distorted-pole
(or standard, or separable) coordinates and back, with the chart and frame given
(docs/math.md, sections 1 to 5)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import angles_to_world, world_to_angles

from ..errors import check_count
from .context import Context
from .fields import Number, Vector3
from .region.params import ChartParams
from .region.resolve import chart_of, frame_of
from .rows import JsonCapability
from .warnings import WarnedAnswer


class PointsRequest(ChartParams):
    """Points to transform."""

    points: Annotated[list[Vector3], Field(min_length=1, fail_fast=True)] = Field(
        description="World points [[x, y, z], ...]."
    )
    center: Vector3 = Field([0.0, 0.0, 0.0], description="The centre c, world coordinates.")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "points": [[0.0, 0.0, -1.0], [1.0, 0.5, -0.2]],
                    "method": "distorted",
                    "sigma": 0.3,
                    "rotation": {"pole": [0.0, 1.0, 0.0], "up": [0.0, 0.0, 1.0]},
                }
            ]
        }
    )


class InverseRequest(ChartParams):
    """Angles to turn back into points."""

    theta: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Polar angles in [0, pi] (radians)."
    )
    phi: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Azimuths in [-pi, pi] (radians), one per theta."
    )
    r: list[Number] | Number | None = Field(
        None, description="Distances from the centre (one per theta, or one for all); default 1."
    )
    center: Vector3 = Field([0.0, 0.0, 0.0], description="The centre c, world coordinates.")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [{"theta": [1.2, 2.0], "phi": [-1.0, -2.5], "r": 1.0, "sigma": 0.3}]
        }
    )

    @model_validator(mode="after")
    def _one_value_per_point(self) -> InverseRequest:
        n = len(self.theta)
        if len(self.phi) != n:
            raise ValueError(
                f"theta, phi: one phi per theta; got {n} theta and {len(self.phi)} phi"
            )
        if isinstance(self.r, list) and len(self.r) != n:
            raise ValueError(
                f"theta, r: one r per theta (or a single number); got {n} theta and {len(self.r)} r"
            )
        return self


@dataclass(frozen=True)
class Angles:
    """(k,) float each: the coordinates of points, radians and distances."""

    theta: np.ndarray
    phi: np.ndarray
    r: np.ndarray


def points_to_angles(request: PointsRequest, ctx: Context) -> Angles:
    """World points to ``(theta, phi, r)`` (:func:`transforms.world_to_angles`)."""
    check_count(len(request.points), ctx.settings.max_points, "points")
    points = np.asarray(request.points, dtype=np.float64)
    chart = chart_of(request)  # before the frame: a bad cap is named first
    frame = frame_of(request, np.asarray(request.center, dtype=np.float64))
    theta, phi, r = world_to_angles(points, frame, chart, threads=ctx.threads)
    return Angles(theta, phi, r)


def angles_to_points(request: InverseRequest, ctx: Context) -> np.ndarray:
    """(k, 3) float: ``(theta, phi, r)`` back to world points
    (:func:`transforms.angles_to_world`)."""
    check_count(len(request.theta), ctx.settings.max_points, "theta")
    chart = chart_of(request)
    frame = frame_of(request, np.asarray(request.center, dtype=np.float64))
    r = 1.0 if request.r is None else request.r
    return angles_to_world(request.theta, request.phi, r, frame, chart)


class PointsResponse(WarnedAnswer):
    theta: list[float] = Field(description="Polar angles, radians, in [0, pi].")
    phi: list[float] = Field(description="Azimuths, radians, in (-pi, pi].")
    r: list[float] = Field(description="Distances from the centre.")

    @classmethod
    def of(cls, angles: Angles) -> PointsResponse:
        return cls.build(theta=angles.theta, phi=angles.phi, r=angles.r)


class InverseResponse(WarnedAnswer):
    points: list[list[float]] = Field(description="World points [[x, y, z], ...].")

    @classmethod
    def of(cls, points: np.ndarray) -> InverseResponse:
        return cls.build(points=points)


ROWS = (
    JsonCapability(
        name="points",
        path="/v1/points",
        summary="Points to (theta, phi, r)",
        description="World points to distorted-pole (or standard, or separable) coordinates, "
        "radians:\n``theta`` the polar angle from local +Z, ``phi`` the azimuth from +X "
        "towards +Y.\nBody: JSON, as the PointsRequest schema.",
        request=PointsRequest,
        operation=points_to_angles,
        response=PointsResponse,
    ),
    JsonCapability(
        name="points_inverse",
        path="/v1/points/inverse",
        summary="(theta, phi, r) to points",
        description="Coordinates back to world points, with the same parameters as "
        "/v1/points.\nBody: JSON, as the InverseRequest schema.",
        request=InverseRequest,
        operation=angles_to_points,
        response=InverseResponse,
    ),
)
