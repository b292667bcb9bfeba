"""JSON answers encoded straight from numpy arrays (orjson: no per-float Python work), and
the Server-Timing header."""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager

import numpy as np
import orjson
from pydantic import BaseModel

from .jobs import current_deadline

JSON = "application/json"


def encode(answer: BaseModel) -> bytes:
    """An answer (a response model of :mod:`service.schemas`) as JSON bytes: the fields it
    was built with, in the model's order; numpy arrays become lists.

    Raises
    ------
    ValueError
        A NaN or Inf anywhere: an answer never carries one (it would be a bug).
    """
    payload = plain(answer)
    _check_finite(payload)
    return orjson.dumps(payload, option=orjson.OPT_SERIALIZE_NUMPY)


def plain(value):
    """``value`` with every model turned into a dict of the fields it was given, in the order
    given (numpy arrays and enums are left to orjson)."""
    if isinstance(value, BaseModel):
        names = getattr(value, "_order", None) or [
            name for name in type(value).model_fields if name in value.model_fields_set
        ]
        return {name: plain(getattr(value, name)) for name in names}
    if isinstance(value, list) and value and isinstance(value[0], (BaseModel, type(None))):
        return [plain(item) for item in value]
    return value


def _check_finite(value) -> None:
    if isinstance(value, dict):
        for item in value.values():
            _check_finite(item)
    elif isinstance(value, (list, tuple)):
        for item in value:
            if isinstance(item, (dict, list, tuple, float, np.ndarray)):
                _check_finite(item)
    elif isinstance(value, np.ndarray):
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            raise ValueError("an answer would carry a NaN or Inf")
    elif isinstance(value, float) and not np.isfinite(value):
        raise ValueError("an answer would carry a NaN or Inf")


class Timings:
    """Named durations for a ``Server-Timing`` header (RFC-style ``name;dur=ms``).

    Each stage starts only before the job's deadline (:mod:`service.jobs`): a job past its
    time limit stops at its next stage instead of running on unseen.
    """

    def __init__(self) -> None:
        self.durations: dict[str, float] = {}

    @contextmanager
    def measure(self, name: str):
        deadline = current_deadline.get()
        if deadline is not None:
            deadline.check()
        start = time.perf_counter()
        try:
            yield
        finally:
            self.durations[name] = self.durations.get(name, 0.0) + time.perf_counter() - start

    def timed(self, name: str, call: Callable):
        with self.measure(name):
            return call()

    def header(self) -> str:
        return ", ".join(
            f"{name};dur={seconds * 1e3:.1f}" for name, seconds in self.durations.items()
        )
