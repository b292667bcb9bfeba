"""Answers: response models built from a use-case's arrays without validation
(:class:`Answer`), and encoded straight from them to JSON (orjson: no per-float Python work).

Each answer is built through its model from a use-case's result (``Model.of(result)``, the
presenters of :mod:`service.capabilities`) and encoded by :func:`encode`. Building skips
pydantic's validation, so that a million-vertex answer keeps its numpy arrays (encoded in C,
with no Python loop over floats); :meth:`Answer.build` still refuses a field the model does
not have or a missing one, and a test validates every route's answer against the document.
"""

from __future__ import annotations

import numpy as np
import orjson
from pydantic import BaseModel, PrivateAttr

JSON = "application/json"


def encode(answer: BaseModel) -> bytes:
    """An answer (an :class:`Answer`) as JSON bytes: the fields it
    was built with, in the model's order; numpy arrays become lists.

    Raises
    ------
    ValueError
        A NaN or Inf anywhere: an answer never carries one (it would be a bug).
    """
    return orjson.dumps(checked(answer), option=orjson.OPT_SERIALIZE_NUMPY)


def checked(answer: BaseModel) -> dict:
    """``answer`` as :func:`plain` makes it, checked for a NaN or Inf (the forms built from
    the JSON answer check it as the JSON does).

    Raises
    ------
    ValueError
        A NaN or Inf anywhere.
    """
    payload = plain(answer)
    _check_finite(payload)
    return payload


def plain(value):
    """``value`` with every model turned into a dict of the fields it was given, in the order
    given (numpy arrays and enums are left to orjson)."""
    if isinstance(value, BaseModel):
        return {name: plain(item) for name, item in built_fields(value)}
    if isinstance(value, list) and value and isinstance(value[0], (BaseModel, type(None))):
        return [plain(item) for item in value]
    return value


def built_fields(model: BaseModel) -> list[tuple[str, object]]:
    """The fields ``model`` was built with and their values, in the order they are encoded
    (the JSON's and the other forms' that follow it, such as the Arrow stream)."""
    names = getattr(model, "_order", None) or [
        name for name in type(model).model_fields if name in model.model_fields_set
    ]
    return [(name, getattr(model, name)) for name in names]


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


class Answer(BaseModel):
    """A response model whose instances are built from arrays without validation."""

    #: The fields given to :meth:`build`, in that order: the order they are encoded in.
    _order: tuple[str, ...] = PrivateAttr(default=())

    @classmethod
    def build(cls, **values):
        """An instance holding ``values`` as they are (numpy arrays included); only the
        fields given are encoded.

        Raises
        ------
        TypeError
            A name that is not a field, or a required field missing: a bug, never the
            client's fault.
        """
        cls._check_names(values.keys())
        answer = cls.model_construct(**values)
        answer._order = tuple(values)
        return answer

    @classmethod
    def rows(cls, present, **columns) -> Rows:
        """Many answers of this model at once, from equally long columns of field values:
        one dict a row (None where ``present`` is false). For long lists (a million hits),
        where an instance a row would cost ten times more; the names are checked once.
        """
        cls._check_names(columns.keys())
        names = list(columns)
        return Rows(
            (
                dict(zip(names, values, strict=True)) if keep else None
                for keep, *values in zip(present, *columns.values(), strict=True)
            ),
            columns,
            present,
        )

    @classmethod
    def _check_names(cls, names) -> None:
        fields = cls.model_fields
        unknown = names - fields.keys()
        missing = {name for name, f in fields.items() if f.is_required()} - names
        if unknown or missing:
            raise TypeError(f"{cls.__name__}: unknown {sorted(unknown)}, missing {sorted(missing)}")


class Rows(list):
    """The rows :meth:`Answer.rows` makes (a list: JSON writes it as one), which keeps the
    columns they were made of and where a row is present, for the forms that answer columns
    (Arrow)."""

    def __init__(self, rows, columns: dict, present):
        super().__init__(rows)
        self.columns, self.present = columns, present
