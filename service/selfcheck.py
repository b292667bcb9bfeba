"""A start-up check that the transform core works on this machine: flatten the scalp of a
bundled scan and summarise the result (``/readyz`` answers once it has passed); and the
health answer."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from transforms.kernels import compile_kernels

from .capabilities.context import Context
from .capabilities.region.params import MeshParams
from .capabilities.region.resolve import MeshInput, flatten
from .encoding import Answer
from .meshio import format_of, read_mesh
from .outputs.picture import energy_text
from .samples import SAMPLES
from .settings import Settings

SAMPLE = "fsaverage-head.ply"
#: The scalp: faces whose centroid is within 70 degrees of up (+Z in the sample's RAS axes)
#: seen from the bounding-box centre; the cap around -Z (the neck).
SCALP_PARAMS = {
    "sigma": 0.3,
    "rotation": {"pole": [0.0, 0.0, -1.0], "up": [0.0, 1.0, 0.0]},
    "region": {"cone": {"axis": [0.0, 0.0, 1.0], "half_angle_deg": 70.0}},
}


@dataclass(frozen=True)
class SelfCheck:
    """What the start-up flatten found."""

    sample: str
    faces: int
    seam_free: bool
    margin_deg: float
    isometric_p50: float
    isometric_p95: float
    seconds: float
    energy: str = ""
    kernels_seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.seam_free and bool(np.isfinite([self.isometric_p50, self.isometric_p95]).all())

    def __str__(self) -> str:
        verdict = "seam-free" if self.seam_free else "NOT seam-free"
        return (
            f"self-check: scalp of {self.sample} ({self.faces:,} faces) flattened {verdict} "
            f"in {self.seconds * 1e3:.0f} ms, margin {self.margin_deg:.1f} deg, "
            f"{self.energy}; compiled kernels ready in {self.kernels_seconds:.1f} s"
        )


def run_self_check() -> SelfCheck:
    """Compile (or load) the numba kernels, so that no request waits for them
    (:func:`transforms.kernels.compile_kernels`); then flatten the scalp of ``SAMPLE`` with
    the default method (distorted, sigma 0.3), read and resolved the way a request would
    be."""
    kernels = compile_kernels()
    data = SAMPLES[SAMPLE].path.read_bytes()
    settings = Settings()
    mesh = read_mesh(data, format_of(SAMPLE, None), settings.limits)
    params = MeshParams.model_validate(SCALP_PARAMS)
    start = time.perf_counter()
    region = flatten(MeshInput(mesh, params), Context(settings))
    flat = region.flat
    v = flat.validation
    return SelfCheck(
        sample=SAMPLE,
        faces=len(region.faces),
        seam_free=v.seam_free,
        margin_deg=min(v.margin_deg_seam, v.margin_deg_north, v.margin_deg_south),
        isometric_p50=(flat.trusted or flat.distortion).isometric.p50,
        isometric_p95=(flat.trusted or flat.distortion).isometric.p95,
        seconds=time.perf_counter() - start,
        energy=energy_text(flat),
        kernels_seconds=kernels,
    )


# The answer of /healthz and /readyz (no docstring: it would be the schema's description).
class Health(Answer):
    status: str = "ok"
