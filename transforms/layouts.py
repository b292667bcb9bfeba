"""The 2D layouts a flattened region can be returned in (docs/math.md, section 7: metrics
are measured on the layout actually returned).

* ``theta_phi``: the paper's, ``(x, y) = (phi, theta)``.
* ``mercator``: ``x = phi``, ``y = ln tan((pi - theta) / 2)`` in the distorted frame. The
  Mercator projection is conformal on the sphere, so apart from the radial projection from
  the centre (and the warp, itself conformal) it keeps angles; it stretches areas away from
  ``theta = pi / 2``.

For measuring, every layout is given with its second coordinate increasing with ``theta``
(``ln tan(theta / 2) = -y`` for Mercator): a reflection changes no singular value, and the
orientation test for folded triangles then reads the same for all layouts.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np

#: Sign of a front-facing triangle's signed area in the (phi, theta) layout, every method (the
#: charts keep orientation alike: docs/math.md, section 6).
LAYOUT_ORIENTATION = -1

#: Mercator's y is infinite at theta = 0 and pi (the singular points); theta is kept this far
#: inside, so such a vertex gets a large finite y (its triangles are flagged by validation).
MERCATOR_THETA_MARGIN = 1e-12


class Layout(StrEnum):
    """How ``(theta, phi)`` become plane coordinates."""

    THETA_PHI = "theta_phi"
    MERCATOR = "mercator"

    @property
    def s_sign(self) -> int:
        """+1 or -1: ``s = s_sign * y`` grows with theta, as the pictures' rows, the GLB's
        ``v`` and the pixel grid run (Mercator's ``y`` runs against theta)."""
        return 1 if self is Layout.THETA_PHI else -1

    def front_orientation(self, winding: int) -> int:
        """The sign of a front-facing triangle's signed area in the ``(x, y)`` plane of this
        layout, for a region whose file winding is ``winding`` (+1 outward, -1 inward):
        ``LAYOUT_ORIENTATION`` in the ``(phi, theta)`` plane, turned over by ``s_sign``."""
        return LAYOUT_ORIENTATION * winding * self.s_sign


def layout_xy(theta: np.ndarray, phi: np.ndarray, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """Plane coordinates of the layout.

    Parameters
    ----------
    theta, phi : (n,) float
    layout : Layout

    Returns
    -------
    x, y : (n,) float
    """
    if Layout(layout) is Layout.THETA_PHI:
        return phi, theta
    return phi, -measured_second(theta, layout)


def measured_second(theta: np.ndarray, layout: Layout) -> np.ndarray:
    """(n,) float: the layout's second coordinate as it is measured (increasing with theta):
    ``theta`` itself, or ``ln tan(theta / 2)``."""
    if Layout(layout) is Layout.THETA_PHI:
        return theta
    kept = np.clip(theta, MERCATOR_THETA_MARGIN, np.pi - MERCATOR_THETA_MARGIN)
    return np.log(np.tan(0.5 * kept))
