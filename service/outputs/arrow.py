"""The Arrow form of a JSON answer (``application/vnd.apache.arrow.stream``): an Arrow IPC
stream of one record batch of one row. Each array of numbers of the answer's models is a
column named by its dotted path (``vertices.x``, ``faces.vertices``,
``zones.0.partial_faces``: a list of models counts its items from 0), holding exactly the
JSON's numbers; the rest of the answer, without those fields, is JSON in the schema's
metadata under ``meshflat``.

A column is a list (one row: the lengths differ) of the array's items: of the numbers for an
array ``(n,)``, of fixed-size lists of ``k`` numbers for ``(n, k)`` (``faces.vertices``: a
list of fixed-size lists of 3), of fixed-size lists of ``p`` such lists for ``(n, p, k)``
(``/v1/strands``' ``points``). Integers are int32 (int64 for an array with a value beyond
int32); floats are float64, bit for bit the double the JSON's text denotes (a
float32 array goes through its JSON text); a null inside an array is a null of the column.
A list of rows whose fields are all arrays of numbers (``/v1/locate``'s hits, made by
:meth:`~service.encoding.Answer.rows`) is a column a field (``hits.face``, ``hits.point``),
null where the JSON's row is null. What is not an array of numbers (strings, booleans,
objects, rows with a string, an empty or null field, a ragged list) stays in the metadata.

Written by nanoarrow (its C library's IPC writer): the arrays are handed over as buffers, so
a million-vertex answer has no Python loop over its numbers.
"""

from __future__ import annotations

import io
from collections.abc import Callable

import nanoarrow as na
import numpy as np
import orjson
from nanoarrow.ipc import StreamWriter
from pydantic import BaseModel

from ..encoding import Rows, built_fields, checked, plain

#: The schema metadata's key of the rest of the answer (JSON).
METADATA_KEY = "meshflat"
#: What writing an Arrow answer may hold per byte of its columns' numbers (8 bytes a number):
#: the numbers converted (ids to int32, a list's numbers), nanoarrow's message, the stream
#: and the bytes answered; about 2.3 counted for a 1.13M-face flatten (46 MB answered for
#: 70 MB of numbers), with room. Charged on top of the job's allowance, which holds the
#: JSON encoding's larger peak (some 200 MB for that flatten) though Arrow replaces it.
ARROW_BYTES_PER_BYTE = 3
#: The columns' number types, by the numpy type that holds them.
_TYPES = {
    np.dtype(np.int32): na.int32(),
    np.dtype(np.int64): na.int64(),
    np.dtype(np.float64): na.float64(),
}


class Column:
    """An array of the answer as its column holds it: ``values`` (int32, int64 or float64)
    and, where it has nulls (one dimension only), ``valid`` (false at a null)."""

    def __init__(self, values: np.ndarray, valid: np.ndarray | None = None):
        self.values, self.valid = values, valid

    def arrow(self):
        """The column: a list of one row holding the items (a number each; for ``(n, k)`` a
        fixed-size list of ``k``, for ``(n, p, k)`` one of ``p`` such lists), over the
        numbers' buffer as it is."""
        values = self.values
        kind = _TYPES[values.dtype]
        flat = np.ascontiguousarray(values).reshape(-1)
        # The nulls are the items' (a number, or a row's fixed-size list).
        bitmap = None if self.valid is None else np.packbits(self.valid, bitorder="little")
        leaf = bitmap if values.ndim == 1 else None
        items = na.c_array_from_buffers(kind, length=flat.size, buffers=[leaf, flat])
        for axis in range(values.ndim - 1, 0, -1):  # (n, p, 3): lists of p lists of 3
            items = na.c_array_from_buffers(
                na.fixed_size_list(items.schema, values.shape[axis]),
                length=int(np.prod(values.shape[:axis])),
                buffers=[bitmap if axis == 1 else None],
                children=[items],
            )
        offsets = np.array([0, len(values)], dtype=np.int32)
        return na.c_array_from_buffers(
            na.list_(items.schema), length=1, buffers=[None, offsets], children=[items]
        )


def arrow_stream(answer: BaseModel, charge: Callable[[int], None]) -> bytes:
    """``answer`` (an :class:`~service.encoding.Answer`, as the JSON encoder is given it) as
    an Arrow IPC stream; what each column takes is given to ``charge`` (bytes) before it is
    built.

    Raises
    ------
    ValueError
        A NaN or Inf anywhere, as for the JSON answer.
    """
    checked(answer)
    columns: dict[str, Column] = {}
    rest = _split(answer, "", columns, charge)
    arrays = [column.arrow() for column in columns.values()]
    struct = na.struct(
        {path: array.schema for path, array in zip(columns, arrays, strict=True)},
        nullable=False,
    )
    metadata = {METADATA_KEY: orjson.dumps(rest, option=orjson.OPT_SERIALIZE_NUMPY)}
    batch = na.c_array_from_buffers(
        na.Schema(struct, metadata=metadata), length=1, buffers=[None], children=arrays
    )
    out = io.BytesIO()
    with StreamWriter.from_writable(out) as writer:
        writer.write_stream(batch)
    return out.getvalue()


def column_of(value) -> Column | None:
    """``value`` as a column when it is a non-empty, rectangular array of numbers (nulls
    allowed in one dimension), else None."""
    if isinstance(value, np.ndarray):
        array = value
    elif isinstance(value, (list, tuple)) and len(value) > 0:
        try:
            array = np.asarray(value)
        except ValueError:  # ragged
            return None
    else:
        return None
    valid = None
    if array.dtype == object and array.ndim == 1:
        valid = np.not_equal(array, None)
        try:
            present = np.asarray(array[valid].tolist())
        except ValueError:
            return None
        if present.dtype.kind not in "iuf" or present.ndim != 1:
            return None
        array = np.zeros(len(valid), dtype=present.dtype)
        array[valid] = present
    if array.dtype.kind not in "iuf" or array.ndim == 0 or array.size == 0:
        return None
    if array.dtype == np.uint64 and array.max() > np.iinfo(np.int64).max:
        return None  # no int64 holds it: the JSON's digits stay the reference
    return Column(_as_json_numbers(array), valid)


def _as_json_numbers(array: np.ndarray) -> np.ndarray:
    """The numbers as the JSON has them: integers as int32 when they all fit (every id
    within the service's limits does: an Int32Array in Arrow JS, where int64 is a
    BigInt64Array, and half the bytes), else int64; float64 as it is; a narrower float as
    the double its shortest text denotes (what the JSON says, and a JSON parser reads)."""
    if array.dtype.kind in "iu":
        low, high = np.iinfo(np.int32).min, np.iinfo(np.int32).max
        fits = array.dtype.itemsize < 4 or (array.min() >= low and array.max() <= high)
        return array.astype(np.int32 if fits else np.int64, copy=False)
    if array.dtype == np.float64:
        return array
    return array.astype(str).astype(np.float64)


def _split(value, path: str, columns: dict[str, Column], charge: Callable[[int], None]):
    """The JSON of ``value`` without its models' arrays of numbers, which go to ``columns``
    by their dotted paths."""
    if isinstance(value, BaseModel):
        rest = {}
        for name, item in built_fields(value):
            dotted = f"{path}{name}"
            found = _field_columns(item, dotted, charge)
            if found is None:
                rest[name] = _split(item, f"{dotted}.", columns, charge)
            else:
                columns |= found
        return rest
    if isinstance(value, list) and any(isinstance(item, BaseModel) for item in value):
        return [_split(item, f"{path}{k}.", columns, charge) for k, item in enumerate(value)]
    return plain(value)


def _field_columns(value, path: str, charge: Callable[[int], None]) -> dict | None:
    """The columns of a model's field: itself when it is an array of numbers, a column a
    field for rows whose fields all are; None when it stays JSON."""
    if isinstance(value, Rows):
        return _row_columns(value, path, charge)
    if not _may_be_numbers(value):
        return None
    charge(ARROW_BYTES_PER_BYTE * _size(value))
    column = column_of(value)
    return None if column is None else {path: column}


def _row_columns(rows: Rows, path: str, charge: Callable[[int], None]) -> dict | None:
    """Rows (:meth:`~service.encoding.Answer.rows`, ``/v1/locate``'s hits) whose every
    field is an array of numbers as a column a field (``hits.face``, ``hits.point``), taken
    from the columns they were made of, each null where a row is; None when a field is not
    (``/v1/measure``'s overlaps name their zones), and the rows stay JSON."""
    if len(rows) == 0:
        return None
    present = np.asarray(rows.present, dtype=bool)
    found = {}
    for name, values in rows.columns.items():
        charge(ARROW_BYTES_PER_BYTE * _size(values))
        column = column_of(values)
        if column is None or column.valid is not None:
            return None
        found[f"{path}.{name}"] = Column(column.values, None if present.all() else present)
    return found


def _may_be_numbers(value) -> bool:
    """Whether ``value`` may be an array of numbers (its first item tells a list of
    objects or strings, which is not)."""
    if isinstance(value, np.ndarray):
        return True
    return (
        isinstance(value, (list, tuple))
        and len(value) > 0
        and not isinstance(value[0], (BaseModel, dict, str))
    )


def _size(value) -> int:
    """The bytes of ``value``'s numbers as a column holds them (8 a number), counted by its
    first items (a list of lists is rectangular, or no column)."""
    count = 1
    while isinstance(value, (list, tuple, np.ndarray)) and len(value) > 0:
        count, value = count * len(value), value[0]
    return 8 * count
