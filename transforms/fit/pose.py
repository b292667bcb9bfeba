"""The fit in the region's own frame (docs/math.md, sections 8 and 9): its answer depends on
the surface and the caller's choices only, not on how the mesh is posed or its unit.

The fit's stages read world axes and lengths in many places (the hull's sample of
directions, the kernel's box, the sigma search's ties, the refinement's steps, tolerances
relative to the region's size); rather than making each pose-free, the whole fit runs on the
region's own coordinates (:class:`transforms.ownframe.OwnFrame`: centred on its area
centroid, turned to its principal axes, divided by its RMS radius), and its answer is taken
back: the centre moved, the rotation turned, the lengths scaled. The region is flattened on
every face in the input's own coordinates with that frame, so that the answer's params,
sent back, give the same map to the last bit; its angles, validation and isometric energy
(section 7: the layout is scaled to the region's 3D area, so a uniform scale changes no
energy) are the same in any pose up to rounding.

The own coordinates are found after a scale by a power of two (exact), so that no moment
of a huge or tiny mesh over- or underflows.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..arrays import as_direction, as_faces, as_points, as_vector, unit_scale
from ..errors import TransformInputError
from ..frames import Frame
from ..ownframe import OwnFrame
from ..viewpoint import check_center_sees_area
from .explain import Fit
from .problem import FitFixed


@dataclass(frozen=True)
class Posed:
    """A region in its own frame.

    Attributes
    ----------
    points : (n, 3) float, every input vertex in the region's own coordinates
    world_points : (n, 3) float, the input's vertices, checked
    faces : (m, 3) int, checked
    fixed : FitFixed, the caller's choices turned into the own frame
    given : FitFixed, the caller's choices as given (kept exactly in the answer)
    default_center : (3,) float or None, likewise
    own : OwnFrame, of the region scaled by ``unit``
    unit : float, the power of two the input was scaled by before ``own`` was found
    """

    points: np.ndarray
    world_points: np.ndarray
    faces: np.ndarray
    fixed: FitFixed
    given: FitFixed
    default_center: np.ndarray | None
    own: OwnFrame
    unit: float

    @classmethod
    def of(cls, vertices, faces, fixed: FitFixed, default_center=None) -> Posed:
        """The region of ``faces`` over ``vertices`` and the caller's ``fixed`` choices (and
        the defaults' centre, if any) in the region's own frame.

        Raises
        ------
        TransformInputError
            Bad vertices or faces, no faces, every face of zero area, a fixed centre from which
        every face is seen edge-on.
        """
        points = as_points(vertices, "vertices")
        faces = as_faces(faces, len(points))
        if len(faces) == 0:
            raise TransformInputError("faces", "the region has no faces")
        if fixed.center is not None:
            # Refused in the caller's coordinates, which its message quotes.
            check_center_sees_area(points, faces, as_vector(fixed.center, "center"))
        unit = unit_scale(float(np.abs(points[faces]).max()))
        zero_area = TransformInputError("faces", "every face of the region has zero area")
        try:
            with np.errstate(divide="ignore", invalid="ignore"):  # no area: refused below
                own = OwnFrame.of_triangles(points * unit, faces)
        except np.linalg.LinAlgError:  # its moments are NaN
            raise zero_area from None
        if not (own.scale > 0 and np.isfinite(own.origin).all() and np.isfinite(own.axes).all()):
            raise zero_area
        posed = cls(points, points, faces, fixed, fixed, default_center, own, unit)
        return replace(
            posed,
            points=own.to_own(points * unit),
            fixed=FitFixed(
                center=posed.point_to_own(fixed.center, "center"),
                rotation=(
                    None
                    if fixed.rotation is None
                    else Frame.from_matrix(fixed.rotation.rotation @ own.axes.T)
                ),
                up=None
                if fixed.up is None
                else own.directions_to_own(as_direction(fixed.up, "up")[None])[0],
                sigma=fixed.sigma,
            ),
            default_center=posed.point_to_own(default_center, "default_center"),
        )

    def point_to_own(self, point, field: str) -> np.ndarray | None:
        """A world point (or None) in the own frame."""
        if point is None:
            return None
        return self.own.to_own(as_vector(point, field)[None] * self.unit)[0]

    @property
    def length(self) -> float:
        """World length of one own unit."""
        return self.own.scale / self.unit

    def frame_of(self, center: np.ndarray, rotation: np.ndarray) -> Frame:
        """The world frame of an own-frame centre and rotation; what the caller fixed exactly
        as given."""
        own, given = self.own, self.given
        if given.center is not None:
            world_center = as_vector(given.center, "center")
        else:
            world_center = own.from_own(np.asarray(center)[None])[0] / self.unit
        world_rotation = np.asarray(rotation) @ own.axes
        if given.rotation is not None:
            world_rotation = given.rotation.rotation
        return Frame.from_matrix(world_rotation, world_center)

    def to_world(self, fit: Fit) -> Fit:
        """``fit``, found in the own frame (its region flattened in the input's coordinates
        already), in world terms: its frame (:meth:`frame_of`), the kernel's radius and the
        centre's depth."""
        frame = self.frame_of(fit.frame.center, fit.frame.rotation)
        explanation = fit.explanation
        if explanation is not None:
            explanation = replace(
                explanation,
                kernel_inscribed_radius=explanation.kernel_inscribed_radius * self.length,
                center_depth=explanation.center_depth * self.length,
            )
        return replace(fit, frame=frame, explanation=explanation)

    def flatten_in_world(self, problem) -> None:
        """Make ``problem`` (a :class:`.problem._Problem` of the own points) flatten in the
        input's coordinates, with :meth:`frame_of`."""
        problem.world_points = self.world_points
        problem.world_frame = self.frame_of
