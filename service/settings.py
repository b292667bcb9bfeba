"""Settings from environment variables (``MESHFLAT_*``), read once when the app is built.

Every setting of the service and of ``meshflat serve`` is an environment variable: a
container is configured without a file or a command-line flag.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path

from .meshio import Limits


@dataclass(frozen=True)
class Settings:
    """Limits, access and tuning of the service.

    Attributes
    ----------
    max_upload_bytes : MESHFLAT_MAX_UPLOAD_BYTES, largest request body (and decoded glTF
        buffer); beyond it the answer is 413, decided while the body streams in
    max_vertices, max_faces : MESHFLAT_MAX_VERTICES, MESHFLAT_MAX_FACES, per mesh
    max_points : MESHFLAT_MAX_POINTS, per /v1/points or /v1/locate request
    threads : MESHFLAT_THREADS, threads one request's computation may use
    max_jobs : MESHFLAT_MAX_JOBS, jobs computed at once per process
    max_waiting : MESHFLAT_MAX_WAITING, jobs admitted beyond those (uploading or waiting for
        a slot); a job beyond ``max_jobs + max_waiting`` is refused at once with a 503
    request_timeout : MESHFLAT_REQUEST_TIMEOUT, seconds a job may take from its first byte to
        its answer (a 408 while the body is still arriving, a 504 after)
    api_keys : MESHFLAT_API_KEYS, comma-separated keys; with any, every ``/v1`` route needs one
    api_keys_file : MESHFLAT_API_KEYS_FILE, a file of keys, one per line (a mounted secret)
    cors_origins : MESHFLAT_CORS_ORIGINS, comma-separated origins a browser may call from
    host, port, workers : MESHFLAT_HOST, MESHFLAT_PORT, MESHFLAT_WORKERS, for ``meshflat serve``
    """

    # The reader's limits and these are one set of numbers: the defaults come from Limits.
    max_upload_bytes: int = Limits.max_bytes
    max_vertices: int = Limits.max_vertices
    max_faces: int = Limits.max_faces
    max_points: int = 5_000_000
    threads: int = 1
    max_jobs: int = 2
    max_waiting: int = 6
    request_timeout: float = 60.0
    api_keys: tuple[str, ...] = field(default=(), repr=False)
    api_keys_file: str = ""
    cors_origins: tuple[str, ...] = ()
    host: str = "127.0.0.1"
    port: int = 8000
    workers: int = 1

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> Settings:
        """Read ``MESHFLAT_<FIELD>`` for every field; unset ones keep their defaults.

        Raises
        ------
        ValueError
            A number that is not positive, or a key file that cannot be read (the service
            refuses to start, naming the variable).
        """
        environ = os.environ if environ is None else environ
        values = {}
        for item in fields(cls):
            name = f"MESHFLAT_{item.name.upper()}"
            if name in environ:
                values[item.name] = _parse(name, environ[name].strip(), item.default)
        settings = cls(**values)
        if settings.api_keys_file:
            try:
                text = Path(settings.api_keys_file).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError) as error:
                raise ValueError(
                    f"MESHFLAT_API_KEYS_FILE: cannot read {settings.api_keys_file!r} "
                    f"({type(error).__name__})"
                ) from None
            keys = tuple(line.strip() for line in text.splitlines() if line.strip())
            settings = cls(**{**values, "api_keys": settings.api_keys + keys})
        return settings

    @property
    def limits(self) -> Limits:
        return Limits(
            max_vertices=self.max_vertices,
            max_faces=self.max_faces,
            max_bytes=self.max_upload_bytes,
        )


def _parse(name: str, text: str, default: object) -> object:
    """``text`` as the type of the field's ``default``."""
    if isinstance(default, tuple):
        return tuple(item.strip() for item in text.split(",") if item.strip())
    if isinstance(default, str):
        return text
    kind = type(default)
    try:
        value = kind(text)
    except ValueError:
        value = None
    zero_allowed = name in _MAY_BE_ZERO
    valid = (
        value is not None and math.isfinite(value) and (value > 0 or (zero_allowed and value == 0))
    )
    if not valid:
        noun = "an integer" if kind is int else "a number"
        bound = "0 or more" if zero_allowed else "above 0"
        raise ValueError(f"{name} must be {noun} {bound}, got {text!r}")
    return value


#: Settings for which 0 makes sense (no queue: a job beyond MESHFLAT_MAX_JOBS is refused).
_MAY_BE_ZERO = frozenset({"MESHFLAT_MAX_WAITING"})
