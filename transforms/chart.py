"""A chart: one of the three ways to give a direction its ``(theta, phi)`` (docs/math.md,
sections 1, 3 and 5).

* ``standard``: eq. 1 alone; its cap is ``rho = 90`` degrees (``sigma = 1``).
* ``distorted``: the pole warp ``W_sigma``, then eq. 1 (:mod:`.warp`).
* ``separable``: the paper's alternative (:mod:`.separable`), pole angle ``rho = 2 atan(sigma)``.

All three put the singular points and the seam on the same cap (:mod:`.cap`) and keep
orientation the same way: a triangle that is counter-clockwise seen from outside (its normal
pointing away from the centre) is clockwise in the ``(phi, theta)`` plane, with ``phi`` across
and ``theta`` up (:data:`transforms.layouts.LAYOUT_ORIENTATION`, -1).
"""

from __future__ import annotations

from enum import StrEnum
from functools import partial

import numpy as np

from .arrays import as_points
from .cap import PoleCap
from .errors import TransformInputError
from .frames import Frame
from .separable import separable_angles, separable_inverse
from .spherical import AngleKernel, eq1_angles, points_to_angles, spherical_to_cartesian
from .warp import distorted_inverse, warped_angles


class Method(StrEnum):
    """How directions get their angles (the default first)."""

    DISTORTED = "distorted"
    STANDARD = "standard"
    SEPARABLE = "separable"


class Chart:
    """A method and its cap; maps local points to ``(theta, phi, r)`` and back.

    Immutable; build one with a named constructor:

    >>> chart = Chart.distorted(PoleCap.from_sigma(0.3))
    >>> theta, phi, r = chart.forward([[0.0, -2.0, 0.0]])   # -Y is fixed by every warp
    >>> float(theta[0]), float(phi[0]), float(r[0])
    (1.5707963267948966, -1.5707963267948966, 2.0)
    """

    __slots__ = ("_cap", "_method")

    def __init__(self, method: Method, cap: PoleCap) -> None:
        self._method = method
        self._cap = cap

    @classmethod
    def standard(cls) -> Chart:
        """Eq. 1 with no warp."""
        return cls(Method.STANDARD, PoleCap.standard())

    @classmethod
    def distorted(cls, cap: PoleCap) -> Chart:
        """The pole warp with ``cap.sigma``, then eq. 1."""
        return cls(Method.DISTORTED, cap)

    @classmethod
    def separable(cls, cap: PoleCap) -> Chart:
        """The separable method with pole angle ``cap.rho``."""
        return cls(Method.SEPARABLE, cap)

    @classmethod
    def from_method(cls, method: str | Method, cap: PoleCap | None = None) -> Chart:
        """A chart by method name; ``cap`` is ignored for ``standard`` and required otherwise."""
        try:
            method = Method(method)
        except ValueError:
            names = ", ".join(m.value for m in Method)
            raise TransformInputError("method", f"must be one of {names}, got {method!r}") from None
        if method is Method.STANDARD:
            return cls.standard()
        if cap is None:
            raise TransformInputError(
                "sigma", f"method {method.value!r} needs sigma or a pole angle"
            )
        return cls(method, cap)

    @property
    def method(self) -> Method:
        """How directions get their angles."""
        return self._method

    @property
    def cap(self) -> PoleCap:
        """The cap holding the seam and singular points (90 degrees for ``standard``)."""
        return self._cap

    def __repr__(self) -> str:
        return f"Chart(method={self._method.value!r}, cap={self._cap!r})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Chart):
            return NotImplemented
        return self._method is other._method and self._cap == other._cap

    def __hash__(self) -> int:
        return hash((self._method, self._cap))

    def forward(
        self,
        points_local,
        threads: int = 1,
        field: str = "points_local",
        noun: str = "point",
        row_ids: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Local points to ``(theta, phi, r)``.

        Parameters
        ----------
        points_local : (n, 3) float
        threads : int, threads to spread the blocks over
        field, noun, row_ids : how errors name the input, one row, and each row's id

        Returns
        -------
        theta : (n,) float, in ``[0, pi]``
        phi : (n,) float, in ``(-pi, pi]``
        r : (n,) float

        Raises
        ------
        TransformInputError
            Non-finite coordinates or a point at the centre.
        """
        points = as_points(points_local, field)
        return self.forward_checked(points, None, threads, (field, noun, row_ids))

    def forward_checked(
        self,
        points: np.ndarray,
        frame: Frame | None,
        threads: int,
        naming: tuple,
        rows_out: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The map on ``(n, 3)`` points already checked (``arrays.as_points``), moved to the
        local frame first when ``frame`` is given. ``naming`` is ``(field, noun, row_ids)``
        for errors; ``rows_out`` (3, n) receives the local rows
        (:func:`.spherical.points_to_angles`)."""
        local_rows = None if frame is None else frame.local_rows
        return points_to_angles(points, self._kernel(), local_rows, threads, *naming, rows_out)

    def _kernel(self) -> AngleKernel:
        if self._method is Method.STANDARD:
            return eq1_angles
        if self._method is Method.DISTORTED:
            return partial(warped_angles, sigma=self._cap.sigma)
        return partial(separable_angles, rho=self._cap.rho)

    def inverse(self, theta, phi, r=1.0) -> np.ndarray:
        """``(theta, phi, r)`` back to local points.

        Parameters
        ----------
        theta : (n,) float, in ``[0, pi]``
        phi : (n,) float, in ``[-pi, pi]``
        r : (n,) float or scalar, ``>= 0``

        Returns
        -------
        (n, 3) float, local frame
        """
        if self._method is Method.STANDARD:
            return spherical_to_cartesian(theta, phi, r)
        if self._method is Method.DISTORTED:
            return distorted_inverse(theta, phi, r, sigma=self._cap.sigma)
        return separable_inverse(theta, phi, r, rho=self._cap.rho)


def world_to_angles(
    points,
    frame: Frame,
    chart: Chart,
    field: str = "points",
    noun: str = "point",
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points to ``(theta, phi, r)``: the frame, then the chart.

    Parameters
    ----------
    points : (n, 3) float, world frame
    frame : Frame, world to local
    chart : Chart
    field, noun : how errors name the input and one of its rows
    threads : int, threads to spread the blocks over

    Returns
    -------
    theta, phi, r : (n,) float

    Raises
    ------
    TransformInputError
        Non-finite coordinates or a point at the centre.
    """
    return chart.forward_checked(as_points(points, field), frame, threads, (field, noun, None))


def angles_to_world(theta, phi, r, frame: Frame, chart: Chart) -> np.ndarray:
    """``(theta, phi, r)`` back to world points: the chart's inverse, then the frame's.

    Parameters
    ----------
    theta, phi, r : (n,) float (``r`` may be a scalar)
    frame : Frame
    chart : Chart

    Returns
    -------
    (n, 3) float, world frame
    """
    return frame.to_world(chart.inverse(theta, phi, r))
