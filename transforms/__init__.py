"""meshflat's transform core: distorted-pole spherical coordinates over numpy arrays.

Pure numpy (and scipy's sparse graphs, linear programs, hulls and minimisers); no web or
file I/O. Every formula follows ``docs/math.md``, which also maps each equation to its
function: ``theta`` is the polar angle from local ``+Z``, ``phi`` the azimuth from ``+X``
towards ``+Y``, in the local frame ``q = R (p - c)``.

>>> import numpy as np
>>> from transforms import Chart, Frame, PoleCap, world_to_angles
>>> frame = Frame.from_pole_up(pole=[0, 0, 1], up=[0, 1, 0])
>>> chart = Chart.distorted(PoleCap.from_sigma(0.3))
>>> theta, phi, r = world_to_angles(np.array([[1.0, 0.0, -1.0]]), frame, chart)
>>> bool(-np.pi < phi[0] < 0)          # far from the pole: no seam, no singular point
True
"""

from .arrays import MAX_ABS_COORDINATE
from .cap import RHO_MAX, RHO_MIN, SIGMA_MAX, SIGMA_MIN, PoleCap, check_rho, check_sigma
from .chart import Chart, Method, angles_to_world, world_to_angles
from .errors import TransformInputError
from .faces import DEGENERATE_RTOL, FaceMeasures, measure_faces
from .fit import Fit, FitBounds, FitExplanation, FitFixed, default_choice, fit_region
from .frames import Frame, check_rotation
from .framing import Framing
from .landmarks import LANDMARK_NAMES, Landmarks
from .layouts import LAYOUT_ORIENTATION, Layout, layout_xy
from .locate import Hits, LocateIndex, locate
from .mapping import MapTriangles
from .margins import arcs_to_point, arcs_to_seam
from .metrics import (
    Distortion,
    FaceDistortion,
    Summary,
    distortion,
    face_distortion,
    weighted_quantile,
)
from .predicates import orient3d_sign
from .region import FlatRegion, assess_region, flatten_region
from .segments import curve_crossings
from .selection import EmptyRegionError
from .separable import separable_forward, separable_inverse, separable_residual
from .spherical import cartesian_to_spherical, spherical_to_cartesian
from .topology import RegionEdges, region_edges
from .untangle import Untangled, untangle
from .validation import STRETCHED_ENERGY, RegionValidation, validate
from .warp import distorted_forward, distorted_inverse, pole_warp
from .zones import Polyline, ZoneCover, cover_zone, lift_curve

__all__ = [
    "DEGENERATE_RTOL",
    "LANDMARK_NAMES",
    "LAYOUT_ORIENTATION",
    "MAX_ABS_COORDINATE",
    "RHO_MAX",
    "RHO_MIN",
    "SIGMA_MAX",
    "SIGMA_MIN",
    "STRETCHED_ENERGY",
    "Chart",
    "Distortion",
    "EmptyRegionError",
    "FaceDistortion",
    "FaceMeasures",
    "Fit",
    "FitBounds",
    "FitExplanation",
    "FitFixed",
    "FlatRegion",
    "Frame",
    "Framing",
    "Hits",
    "Landmarks",
    "Layout",
    "LocateIndex",
    "MapTriangles",
    "Method",
    "PoleCap",
    "Polyline",
    "RegionEdges",
    "RegionValidation",
    "Summary",
    "TransformInputError",
    "Untangled",
    "ZoneCover",
    "angles_to_world",
    "arcs_to_point",
    "arcs_to_seam",
    "assess_region",
    "cartesian_to_spherical",
    "check_rho",
    "check_rotation",
    "check_sigma",
    "cover_zone",
    "curve_crossings",
    "default_choice",
    "distorted_forward",
    "distorted_inverse",
    "distortion",
    "face_distortion",
    "fit_region",
    "flatten_region",
    "layout_xy",
    "lift_curve",
    "locate",
    "measure_faces",
    "orient3d_sign",
    "pole_warp",
    "region_edges",
    "separable_forward",
    "separable_inverse",
    "separable_residual",
    "spherical_to_cartesian",
    "untangle",
    "validate",
    "weighted_quantile",
    "world_to_angles",
]
