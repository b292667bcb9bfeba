"""A start-up check that the transform core works on this machine: flatten the scalp of a
bundled scan and summarise the result."""

from __future__ import annotations

import io
import time
from dataclasses import dataclass

import numpy as np
import trimesh

from transforms import Chart, Frame, PoleCap, flatten_region

from .samples import SAMPLES

SAMPLE = "fsaverage-head.ply"
#: The scalp: faces whose centroid is within this angle of up (+Z in the sample's RAS axes)
#: seen from the bounding-box centre.
SCALP_HALF_ANGLE_DEG = 70.0


@dataclass(frozen=True)
class SelfCheck:
    """What the start-up flatten found."""

    sample: str
    faces: int
    seam_free: bool
    margin_deg: float
    isometric_mean: float
    seconds: float

    @property
    def ok(self) -> bool:
        return self.seam_free and np.isfinite(self.isometric_mean)

    def __str__(self) -> str:
        verdict = "seam-free" if self.seam_free else "NOT seam-free"
        return (
            f"self-check: scalp of {self.sample} ({self.faces:,} faces) flattened {verdict} "
            f"in {self.seconds * 1e3:.0f} ms, margin {self.margin_deg:.1f} deg, "
            f"isometric distortion {self.isometric_mean:.3f}"
        )


def run_self_check() -> SelfCheck:
    """Flatten the scalp of ``SAMPLE`` with the default method (distorted, sigma 0.3)."""
    data = SAMPLES[SAMPLE].path.read_bytes()
    mesh = trimesh.load(io.BytesIO(data), file_type="ply", process=False, force="mesh")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    start = time.perf_counter()
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    directions = vertices[faces].mean(axis=1) - centre
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    scalp = faces[directions[:, 2] >= np.cos(np.radians(SCALP_HALF_ANGLE_DEG))]
    frame = Frame.from_pole_up(pole=[0.0, 0.0, -1.0], up=[0.0, 1.0, 0.0], center=centre)
    flat = flatten_region(vertices, scalp, frame, Chart.distorted(PoleCap.from_sigma(0.3)))
    v = flat.validation
    return SelfCheck(
        sample=SAMPLE,
        faces=len(scalp),
        seam_free=v.seam_free,
        margin_deg=min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south),
        isometric_mean=flat.distortion.isometric.mean,
        seconds=time.perf_counter() - start,
    )
