"""The forbidden cap: where the warp puts the singular points and the seam (docs/math.md,
section 4).

With ``rho = 2 atan(sigma)``, the singular points (pre-images of ``+Z`` and ``-Z``) are
``(0, cos rho, +-sin rho)`` and the seam is the arc of the circle at angle ``rho`` from ``+Y``
on the side ``x < 0``. A region farther than ``rho`` from ``+Y`` is free of both.
"""

from __future__ import annotations

import math

import numpy as np

from .arrays import number
from .errors import TransformInputError

#: Accepted range of sigma. Outside it sigma^2 loses the warp to rounding.
SIGMA_MIN = 1e-6
SIGMA_MAX = 1e6
#: The same range as pole angles, in radians.
RHO_MIN = 2.0 * math.atan(SIGMA_MIN)
RHO_MAX = 2.0 * math.atan(SIGMA_MAX)


class PoleCap:
    """The cap of angular radius ``rho`` around local ``+Y`` that holds the seam and both
    singular points, for warp parameter ``sigma`` (``rho = 2 atan(sigma)``).

    Immutable; build one with a named constructor:

    >>> cap = PoleCap.from_sigma(1.0)
    >>> round(cap.rho_deg, 9)
    90.0
    >>> PoleCap.from_rho_deg(90.0).north.round(12).tolist()
    [0.0, 0.0, 1.0]

    Attributes
    ----------
    sigma : float, the warp parameter (> 0)
    rho : float, the pole angle in radians, in (0, pi)
    """

    __slots__ = ("_rho", "_sigma")

    def __init__(self, sigma: float, rho: float) -> None:
        # Private: the named constructors check and convert; keep both as given.
        self._sigma = sigma
        self._rho = rho

    @classmethod
    def from_sigma(cls, sigma: float) -> PoleCap:
        """The cap of the warp ``W_sigma``.

        Raises
        ------
        TransformInputError
            ``sigma`` not finite or outside ``[SIGMA_MIN, SIGMA_MAX]``.
        """
        sigma = check_sigma(sigma)
        return cls(sigma, 2.0 * math.atan(sigma))

    @classmethod
    def from_rho(cls, rho: float) -> PoleCap:
        """The cap of pole angle ``rho`` (radians).

        Raises
        ------
        TransformInputError
            ``rho`` not finite or outside ``[RHO_MIN, RHO_MAX]`` (within ``(0, pi)``).
        """
        rho = check_rho(rho)
        return cls(_half_angle_tan(rho), rho)

    @classmethod
    def from_rho_deg(cls, rho_deg: float) -> PoleCap:
        """The cap of pole angle ``rho_deg`` degrees (the API's ``pole_angle_deg``)."""
        rho = _check_rho(rho_deg, "pole_angle_deg", math.pi / 180.0)
        return cls(_half_angle_tan(rho), rho)

    @classmethod
    def standard(cls) -> PoleCap:
        """The cap of plain eq. 1 (no warp): ``sigma = 1``, ``rho = 90`` degrees."""
        return cls(1.0, math.pi / 2.0)

    @property
    def sigma(self) -> float:
        """The warp parameter, ``tan(rho / 2)``."""
        return self._sigma

    @property
    def rho(self) -> float:
        """The pole angle in radians, ``2 atan(sigma)``."""
        return self._rho

    @property
    def rho_deg(self) -> float:
        """The pole angle in degrees."""
        return math.degrees(self._rho)

    @property
    def north(self) -> np.ndarray:
        """(3,) float: the singular point mapped to ``theta = 0``, ``(0, cos rho, sin rho)``.

        From ``sigma`` as ``((1 - sigma^2) / (1 + sigma^2), 2 sigma / (1 + sigma^2))``: exact
        for ``sigma = 1`` (``+Z``) and consistent with the warp's own arithmetic.
        """
        return np.array([0.0, self._cos_rho(), self._sin_rho()])

    @property
    def south(self) -> np.ndarray:
        """(3,) float: the singular point mapped to ``theta = pi``, ``(0, cos rho, -sin rho)``."""
        return np.array([0.0, self._cos_rho(), -self._sin_rho()])

    def _cos_rho(self) -> float:
        s2 = self._sigma * self._sigma
        return (1.0 - s2) / (1.0 + s2)

    def _sin_rho(self) -> float:
        return 2.0 * self._sigma / (1.0 + self._sigma * self._sigma)

    def seam_arc(self, n: int = 91) -> np.ndarray:
        """Points along the seam, from the north to the south singular point through ``x < 0``.

        Parameters
        ----------
        n : int, number of points (>= 2)

        Returns
        -------
        (n, 3) float, unit vectors in the local frame
        """
        t = np.linspace(0.0, math.pi, max(int(n), 2))
        sin_rho, cos_rho = self._sin_rho(), self._cos_rho()
        return np.stack(
            [-sin_rho * np.sin(t), np.full_like(t, cos_rho), sin_rho * np.cos(t)], axis=1
        )

    def __repr__(self) -> str:
        return f"PoleCap(sigma={self._sigma!r}, rho_deg={self.rho_deg!r})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PoleCap):
            return NotImplemented
        return self._sigma == other._sigma and self._rho == other._rho

    def __hash__(self) -> int:
        return hash((self._sigma, self._rho))


def _half_angle_tan(rho: float) -> float:
    """``tan(rho / 2)`` by the half-angle form without cancellation (exactly 1 at 90 degrees),
    kept in ``[SIGMA_MIN, SIGMA_MAX]`` (the ends of the rho range may round just outside)."""
    if rho <= math.pi / 2.0:
        sigma = math.sin(rho) / (1.0 + math.cos(rho))
    else:
        sigma = (1.0 - math.cos(rho)) / math.sin(rho)
    return min(max(sigma, SIGMA_MIN), SIGMA_MAX)


def _check_rho(value, field: str, to_radians: float) -> float:
    """``value * to_radians`` as a float in ``[RHO_MIN, RHO_MAX]``, or an error naming ``field``."""
    rho = number(value, field) * to_radians
    if not RHO_MIN <= rho <= RHO_MAX:
        low, high = RHO_MIN / to_radians, RHO_MAX / to_radians
        raise TransformInputError(
            field,
            f"must be finite and in [{low:.6g}, {high:.12g}] "
            f"(inside (0, {math.pi / to_radians:g})), "
            f"got {float(value)!r}",
        )
    return rho


def check_rho(rho) -> float:
    """Return the pole angle ``rho`` (radians) as a float in ``[RHO_MIN, RHO_MAX]``.

    Raises
    ------
    TransformInputError
        Not a number, not finite, or outside the range (which lies inside ``(0, pi)``).
    """
    return _check_rho(rho, "rho", 1.0)


def check_sigma(sigma) -> float:
    """Return ``sigma`` as a float in ``[SIGMA_MIN, SIGMA_MAX]``.

    Raises
    ------
    TransformInputError
        Not a number, not finite, ``<= 0``, or outside the range.
    """
    value = number(sigma, "sigma")
    if not SIGMA_MIN <= value <= SIGMA_MAX:
        raise TransformInputError(
            "sigma", f"must be finite and in [{SIGMA_MIN:g}, {SIGMA_MAX:g}], got {value!r}"
        )
    return value
