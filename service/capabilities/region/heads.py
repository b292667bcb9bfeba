"""Where the head faces and its own frame, as a mesh request's params say them: ``facing``,
the landmarks of ``frame`` and of a ``region.scalp`` (docs/math.md, sections 14 and 18),
checked on the mesh's surface and against a rotation that is given."""

from __future__ import annotations

import numpy as np

from transforms import Frame, Landmarks
from transforms.arrays import as_direction
from transforms.frames import FACING_AGREEMENT_DEG, facing_disagreement_deg

from ...errors import InvalidInput
from ...meshio import Mesh
from .params import AutoPole, MeshParams


def facing_of(params: MeshParams) -> np.ndarray | None:
    """(3,) unit or None: where the face looks, as the request says (docs/math.md, section
    18): ``params.facing``; else the forward direction (14.1) of the landmarks of
    ``frame`` (whose local ``+Z`` it is) or, when meshflat chooses the roll, of a
    ``region.scalp``; else None (the roll as before). Landmarks given are read as checked
    already (by :func:`head_frame` or the region's selection).

    Raises
    ------
    InvalidInput
        ``facing`` with ``frame``, or with the ``up`` of ``{"pole": "auto"}``.
    TransformInputError
        ``facing`` zero.
    """
    if params.facing is not None:
        if params.frame is not None:
            raise InvalidInput(
                "facing",
                "frame's landmarks fix the roll already (local +Z towards the nasion: the "
                "front at the top); leave out facing",
            )
        if isinstance(params.rotation, AutoPole) and params.rotation.up is not None:
            raise InvalidInput(
                "facing", "rotation.up and facing both set the roll about the pole; give one"
            )
        return as_direction(params.facing, "facing")
    if params.frame is not None:
        landmarks, field = params.frame.landmarks, "frame.landmarks"
    elif params.region is not None and params.region.scalp is not None and _roll_free(params):
        landmarks, field = params.region.scalp.landmarks, "region.scalp.landmarks"
    else:
        return None
    _, forward, _ = Landmarks.of(landmarks.model_dump(exclude_none=True), field=field).axes()
    return forward


def _roll_free(params: MeshParams) -> bool:
    """Whether meshflat chooses the roll: no rotation, ``"auto"``, or ``{"pole": "auto"}``
    without ``up``."""
    rotation = params.rotation
    if isinstance(rotation, AutoPole):
        return rotation.up is None
    return rotation is None or rotation == "auto"


def check_facing(rotation: np.ndarray, facing: np.ndarray, what: str) -> None:
    """Refuse a ``rotation`` (3, 3) whose local ``+Z`` is not ``facing``'s part across its
    pole (:func:`transforms.frames.facing_disagreement_deg`).

    Raises
    ------
    InvalidInput
        They disagree by more than ``FACING_AGREEMENT_DEG``.
    TransformInputError
        ``facing`` within ``MIN_FACING_DEG`` of the rotation's pole or its opposite.
    """
    off = facing_disagreement_deg(rotation, facing)
    if off > FACING_AGREEMENT_DEG:
        raise InvalidInput(
            "facing",
            f"{what} puts local +Z {off:.6g} degrees from facing's part across its pole (at "
            f"most {FACING_AGREEMENT_DEG:g}): the rotation fixes the roll; give one of "
            "them, or two that agree (as an answer's params do)",
        )


def head_frame(mesh: Mesh, params: MeshParams) -> Frame | None:
    """The frame of ``params.frame``'s landmarks (:meth:`transforms.Landmarks.frame`), each
    checked on the mesh's surface; None without landmarks."""
    if params.frame is None:
        return None
    landmarks = checked_landmarks(mesh, params.frame.landmarks, "frame.landmarks")
    return landmarks.frame()


def checked_landmarks(mesh: Mesh, given, field: str) -> Landmarks:
    """The landmarks of ``given`` (the params' model), checked as a head's and on the
    mesh's surface; errors name ``field``'s landmark."""
    landmarks = Landmarks.of(given.model_dump(exclude_none=True), field=field)
    landmarks.check_on_surface(mesh.vertices, mesh.faces)
    return landmarks
