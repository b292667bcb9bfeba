"""A region of a mesh flattened in one call: frame, chart, per-face measurements, validation
and distortion metrics (docs/math.md end to end: frames, a method, validation, distortion)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .arrays import INDEX, as_faces, as_points
from .cap import PoleCap
from .chart import Chart
from .errors import TransformInputError
from .faces import FaceMeasures, measure_checked, measure_faces
from .frames import Frame
from .layouts import Layout, layout_xy, measured_second
from .metrics import Distortion, FaceDistortion, distortion_and_trusted, face_distortion
from .topology import representatives, welded_by
from .validation import RegionValidation, validate
from .viewpoint import check_center_sees_area


@dataclass(frozen=True)
class FlatRegion:
    """A flattened region.

    Attributes
    ----------
    vertex_ids : (k,) int, ascending: the rows of the input vertices the region uses
    theta, phi, r : (k,) float, their coordinates (``theta`` polar, ``phi`` azimuth)
    layout : Layout, the 2D layout the metrics were measured on
    x, y : (k,) float, the vertices in that layout
    faces : (m, 3) int, the region's faces as positions in ``vertex_ids``, in input order
    validation : RegionValidation, face lists by position in the region's face list
    distortion : Distortion, over every measured face
    trusted : Distortion or None, over the trusted faces only: neither flagged by the
        validation (stretched faces included) nor degenerate (the same per-face values;
        None when no face is trusted)
    flagged_faces : int, how many faces the validation flags (any reason, each face once)
    weld : (k,) int, for each vertex the position of the lowest at exactly its place
        (:func:`.topology.representatives`; itself when alone): a triangle soup's corners
        are one vertex for all that needs connectivity (docs/math.md, section 8)
    """

    vertex_ids: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    r: np.ndarray
    layout: Layout
    x: np.ndarray
    y: np.ndarray
    faces: np.ndarray
    validation: RegionValidation
    distortion: Distortion
    trusted: Distortion | None
    flagged_faces: int
    weld: np.ndarray

    @property
    def links(self) -> np.ndarray:
        """(m, 3) int: ``faces`` welded (:attr:`weld`): what their edges, boundary loops,
        pieces and neighbourhoods are read from; ``faces`` itself when no vertex repeats
        another's position."""
        return welded_by(self.faces, self.weld)


def flatten_region(
    vertices,
    faces,
    frame: Frame,
    chart: Chart,
    winding: int | None = None,
    threads: int = 1,
    layout: Layout | str = Layout.THETA_PHI,
    distinct: bool = False,
) -> FlatRegion:
    """Flatten the faces of a mesh region and check the result.

    Parameters
    ----------
    vertices : (n, 3) float, the mesh's vertices in the world frame
    faces : (m, 3) int, the region's faces as indices into ``vertices``; at least one
    frame : Frame, the centre and rotation
    chart : Chart, the method and its cap
    winding : +1 or -1 to fix which way normals point (see :func:`.validation.validate`)
    threads : int, threads to share the work
    layout : the 2D layout returned and measured (:mod:`.layouts`)
    distinct : bool, the caller knows that no two of ``vertices`` share a position (it
        welded them already, :func:`.topology.representatives`): the weld is not searched

    Returns
    -------
    FlatRegion

    Raises
    ------
    TransformInputError
        Bad coordinates or indices, a region vertex at the centre (named by its row in
        ``vertices``), no faces, only degenerate faces, or a centre from which every face
        is seen edge-on (:func:`.viewpoint.check_center_sees_area`).
    """
    vertices = as_points(vertices, "vertices")
    faces = as_faces(faces, len(vertices))
    if len(faces) == 0:
        raise TransformInputError("faces", "the region has no faces")
    check_center_sees_area(vertices, faces, frame.center)
    vertex_ids, compact = _compacted(np.ascontiguousarray(faces, dtype=INDEX), len(vertices))
    if len(vertex_ids) == len(vertices):  # every vertex used (the whole mesh): no renumbering
        used = vertices
    else:
        used = vertices[vertex_ids]
    # What is done with is let go as soon as it is (faces, used, rows): the validation's
    # edge classification, the peak of the call, then runs beside less.
    del faces
    weld = np.arange(len(used)) if distinct else representatives(used)
    # The local rows come out of the same pass as the angles; measured without checking
    # again, since everything here was made checked.
    rows = np.empty((3, len(used)))
    theta, phi, r = chart.forward_checked(
        used, frame, threads, ("vertices", "vertex", vertex_ids), rows_out=rows
    )
    del used
    layout = Layout(layout)
    measures = measure_checked(
        rows, compact, measured_second(theta, layout), phi, chart.cap, threads
    )
    del rows  # the measures hold their own, scaled
    links = welded_by(compact, weld)
    validation, metrics, trusted, flagged = _judge(measures, winding, threads, links)
    del links
    x, y = layout_xy(theta, phi, layout)
    return FlatRegion(
        vertex_ids=vertex_ids,
        theta=theta,
        phi=phi,
        r=r,
        layout=layout,
        x=x,
        y=y,
        faces=compact,
        validation=validation,
        distortion=metrics,
        trusted=trusted,
        flagged_faces=flagged,
        weld=weld,
    )


def assess_region(
    vertices_local,
    faces,
    theta,
    phi,
    cap: PoleCap,
    winding: int | None = None,
    threads: int = 1,
    layout_theta=None,
) -> tuple[RegionValidation, Distortion]:
    """Validation and distortion metrics of a region already in the local frame.

    Parameters
    ----------
    vertices_local : (n, 3) float, vertices in the local frame
    faces : (m, 3) int, the region's faces as indices into ``vertices_local``
    theta, phi : (n,) float, the vertices' coordinates from the chart
    cap : PoleCap, the chart's cap
    winding : +1 or -1 to fix which way normals point (see :func:`.validation.validate`)
    threads : int, threads to share the work
    layout_theta : (n,) float or None, the measured layout's second coordinate (see
        :func:`.faces.measure_faces`)

    Returns
    -------
    (RegionValidation, Distortion)
    """
    measures = measure_faces(vertices_local, faces, theta, phi, cap, threads, layout_theta)
    validation, metrics, _, _ = _judge(measures, winding, threads)
    return validation, metrics


def region_face_distortion(
    vertices, flat: FlatRegion, frame: Frame, chart: Chart, threads: int = 1
) -> FaceDistortion:
    """The per-face measures of section 7 over a flattened region (the layout as flattened),
    measured again from ``vertices`` ((n, 3) float, the same the region was flattened from):
    what a picture coloured by distortion shows, face by face.

    Returns
    -------
    FaceDistortion, positions in ``flat.faces`` (the degenerate faces left out)
    """
    local = frame.to_local(np.asarray(vertices, dtype=np.float64)[flat.vertex_ids])
    second = measured_second(flat.theta, flat.layout)
    measures = measure_faces(local, flat.faces, flat.theta, flat.phi, chart.cap, threads, second)
    return face_distortion(measures)


def flagged_mask(
    validation: RegionValidation, n_faces: int, *, stretched: bool = True
) -> np.ndarray:
    """(m,) bool: the faces any of the validation's lists holds; with ``stretched`` False,
    the stretched faces only where another list holds them too (docs/math.md, section 6:
    a stretched face's map is one to one, so what lies on it, sites, still is where the
    map says)."""
    flagged = np.zeros(n_faces, dtype=bool)
    for listed in (
        validation.singular_point_faces,
        validation.seam_faces,
        validation.folded_faces,
        validation.backfacing_faces,
        validation.degenerate_faces,
        validation.stretched_faces if stretched else np.empty(0, dtype=np.intp),
    ):
        flagged[listed] = True
    return flagged


def _judge(
    measures: FaceMeasures, winding: int | None, threads: int, links: np.ndarray | None = None
) -> tuple[RegionValidation, Distortion, Distortion | None, int]:
    """Validation (edges read from ``links``, the faces welded), distortion over every face
    and over the trusted ones, and the count of flagged faces."""
    # One after the other: side by side on two threads they only compete for memory.
    validation = validate(measures, winding, threads, links)
    flagged = flagged_mask(validation, len(measures))
    metrics, trusted = distortion_and_trusted(measures, flagged)
    return validation, metrics, trusted, int(flagged.sum())


@njit(cache=True, nogil=True)
def _compacted(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ``faces`` ((m, 3) int32, ids below ``n``) use, ascending ((k,) int64), and
    the faces as positions among them ((m, 3) int32; ``faces`` itself when every vertex is
    used): one pass to mark, one to number, one to renumber."""
    used = np.zeros(n, dtype=np.bool_)
    for f in range(faces.shape[0]):
        for c in range(3):
            used[faces[f, c]] = True
    position = np.empty(n, dtype=np.int32)
    k = 0
    for v in range(n):
        if used[v]:
            position[v] = k
            k += 1
    ids = np.empty(k, dtype=np.int64)
    for v in range(n):
        if used[v]:
            ids[position[v]] = v
    if k == n:
        return ids, faces
    compact = np.empty_like(faces)
    for f in range(faces.shape[0]):
        for c in range(3):
            compact[f, c] = position[faces[f, c]]
    return ids, compact
