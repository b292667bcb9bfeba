"""Settings from environment variables (``MESHFLAT_*``), read once when the app is built."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, fields

from .meshio import Limits


@dataclass(frozen=True)
class Settings:
    """Limits and tuning of the service.

    Attributes
    ----------
    max_upload_bytes : MESHFLAT_MAX_UPLOAD_BYTES, largest request body (and decoded glTF
        buffer); beyond it the answer is 413, decided while the body streams in
    max_vertices, max_faces : MESHFLAT_MAX_VERTICES, MESHFLAT_MAX_FACES, per mesh
    max_points : MESHFLAT_MAX_POINTS, per /v1/points or /v1/locate request
    threads : MESHFLAT_THREADS, threads one request's computation may use
    max_jobs : MESHFLAT_MAX_JOBS, requests computed at once; more wait for a slot
    """

    max_upload_bytes: int = 256 * 2**20
    max_vertices: int = 5_000_000
    max_faces: int = 5_000_000
    max_points: int = 5_000_000
    threads: int = 1
    max_jobs: int = 2

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> Settings:
        """Read ``MESHFLAT_<FIELD>`` for every field; unset ones keep their defaults.

        Raises
        ------
        ValueError
            A variable that is not a positive integer (the service refuses to start).
        """
        environ = os.environ if environ is None else environ
        values = {}
        for field in fields(cls):
            name = f"MESHFLAT_{field.name.upper()}"
            if name in environ:
                text = environ[name].strip()
                if not text.isdigit() or int(text) < 1:
                    raise ValueError(f"{name} must be a positive integer, got {text!r}")
                values[field.name] = int(text)
        return cls(**values)

    @property
    def limits(self) -> Limits:
        return Limits(
            max_vertices=self.max_vertices,
            max_faces=self.max_faces,
            max_bytes=self.max_upload_bytes,
        )
