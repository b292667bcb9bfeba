"""The use-cases' own refusals, beside the core's :class:`~transforms.TransformInputError`,
and where the fields they name lie in a request (:class:`ErrorPlaces`).

They know no HTTP: :func:`service.problems.problem_of` turns each into its problem+json
answer, placing ``field`` in the request the way it places the core's fields (a parameter
under ``params.`` for a mesh route, a file part by its own name).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from transforms.errors import MAX_LISTED

from .meshio import MeshFormatError


class InvalidInput(Exception):
    """An input the service cannot use, which only the service can tell is wrong (the file
    lacks what the region asks for, two zones overlap, a registration did not hold).

    The detail reads ``{item} ({name}){about}: {message}``: ``params.zones.2 ('crown'), hole
    0: a hole must lie inside the outer ring`` for the field ``zones.2.holes.0``.

    Attributes
    ----------
    field : str, the parameter (dotted, as in ``zones.1.outer``) or file part at fault
    message : str, what is wrong and what would do, in words
    name : str or None, the name the client gave the item (a zone's), shown beside it
    item : str, what the detail names first (default ``field``; a zone for its ring)
    about : str, words after the name (``", outer ring"``)
    indices : tuple of int, the offending vertex, face or point ids, if any
    """

    def __init__(
        self,
        field: str,
        message: str,
        *,
        name: str | None = None,
        item: str | None = None,
        about: str = "",
        indices: Sequence[int] = (),
    ) -> None:
        super().__init__(f"{field}: {message}")
        self.field, self.message, self.name = field, message, name
        self.item, self.about = item or field, about
        self.indices = tuple(int(i) for i in indices[:MAX_LISTED])


class OverLimit(Exception):
    """More items than a setting of the service allows (query points, drawn points, sites).

    Attributes
    ----------
    field : str, the parameter that holds them
    count, limit : int
    setting : str, the environment variable that sets the limit
    hint : str, what may be wrong beside the count (a unit that inflates it), or empty
    """

    def __init__(self, field: str, count: int, limit: int, setting: str, hint: str = "") -> None:
        self.message = f"{count:,} items; the limit is {limit:,} ({setting})"
        if hint:
            self.message += f"; {hint}"
        super().__init__(f"{field}: {self.message}")
        self.field, self.count, self.limit, self.setting = field, count, limit, setting


def check_count(
    count: int, limit: int, field: str, setting: str = "MESHFLAT_MAX_POINTS", hint: str = ""
) -> None:
    """Refuse more than ``limit`` items in ``field`` (the refusal adds ``hint``, if any).

    Raises
    ------
    OverLimit
        ``count`` is above ``limit``.
    """
    if count > limit:
        raise OverLimit(field, count, limit, setting, hint)


class UnreadableMesh(Exception):
    """A mesh part that could not be read: ``error`` is the reader's
    (:class:`~service.meshio.MeshFormatError`, a mesh beyond a limit included), ``part`` the
    form's part (or the command line's argument) it came in."""

    def __init__(self, part: str, error: MeshFormatError) -> None:
        super().__init__(f"{part}: {error}")
        self.part, self.error = part, error


class UnknownMesh(Exception):
    """A mesh named by the SHA-256 of its upload (``field``) that this process does not hold:
    never sent to it, or let go since (the cache is a cache, never a store)."""

    def __init__(self, field: str, digest: str) -> None:
        super().__init__(f"{field}: {digest}")
        self.field, self.digest = field, digest


@dataclass(frozen=True)
class ErrorPlaces:
    """Where the fields a core error names lie in a request.

    Attributes
    ----------
    prefix : where the parameters are (``params.`` for a multipart form's JSON part)
    parameters : the names of the parameters (a dotted field counts by its first part);
        None: every field is one
    data : the part every other field is about (the uploaded ``mesh``)
    """

    prefix: str = ""
    parameters: frozenset[str] | None = None
    data: str = ""

    def of(self, name: str) -> str:
        """Where a core error's field lies: a parameter, or else the uploaded data (the core
        names its arguments, and a mesh's arrays are the data's)."""
        name = _NESTED.get(name, name)
        return f"{self.prefix}{name}" if self._parameter(name) else self.data

    def named(self, name: str) -> str:
        """Where a use-case's field lies: a parameter, or else what it names itself (a file
        part, the answer's sites)."""
        return f"{self.prefix}{name}" if self._parameter(name) else name

    def _parameter(self, name: str) -> bool:
        """Whether ``name`` (dotted: its first part counts) is a parameter."""
        return self.parameters is None or name.partition(".")[0] in self.parameters


#: The core's arguments that are parts of a request field: the pole and up of a rotation.
_NESTED = {"pole": "rotation.pole", "up": "rotation.up"}


#: A JSON body: every field is the body's own.
JSON_BODY = ErrorPlaces()
