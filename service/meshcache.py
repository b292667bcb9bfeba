"""The meshes sent once (``POST /v1/meshes``), kept in memory by the SHA-256 of their upload,
with what requests compute from them (a region flattened, its map's triangles, a locate
index): a per-process LRU bounded by bytes, within the memory budget the jobs are admitted by.

It is a cache, never a store: nothing goes to disk, a mesh may be gone at the next request
(evicted, or the request went to another worker or replica), and the client then sends it
again. Each uvicorn worker has its own.

What is kept is counted by its arrays' bytes (:func:`held_bytes`) and taken from the memory
budget (:class:`service.server.jobs.MemoryBudget`): when a job's charge finds no room, the
budget asks :meth:`MeshCache.reclaim` first, which lets go of the least recently used. Every
kept array is made read-only: a step that wrote into one would change later answers.
"""

from __future__ import annotations

import dataclasses
import enum
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

from .capabilities.context import Context
from .capabilities.warnings import Warned
from .meshio import Mesh
from .meshio.mesh import Attributes
from .observability import MESH_CACHE_BYTES, MESH_CACHE_STEPS

T = TypeVar("T")

#: A unit's key: ``(digest,)`` for a mesh, its owner's key and the step's key after it for
#: what was computed from it.
Key = tuple


class Budget(Protocol):
    def take(self, nbytes: int, reclaiming: bool = True) -> bool: ...

    def give(self, nbytes: int) -> None: ...


@dataclass
class _Unit:
    """A mesh or a step's result on one, what it holds (bytes), and the warnings the step
    added (added again to each request that uses it)."""

    value: object
    bytes: int
    warnings: tuple[Warned, ...] = ()


class MeshCache:
    """Meshes by the SHA-256 of their upload, and the steps' results on them; least recently
    used out first once ``capacity`` bytes are held or the ``budget`` has no room; thread-
    safe. A step's result goes out before (or with) its mesh, never after it.

    Parameters
    ----------
    capacity : the most bytes held (0: nothing is kept)
    budget : the memory budget the bytes held are taken from (None: none)
    """

    def __init__(self, capacity: int, budget: Budget | None = None) -> None:
        self.capacity = capacity
        self._budget = budget
        self._units: OrderedDict[Key, _Unit] = OrderedDict()  # least recently used first
        self._keys: dict[int, Key] = {}  # id of a held value -> its key
        self._lock = threading.Lock()
        self.bytes = 0

    def __len__(self) -> int:
        return len(self._units)

    # -- meshes ------------------------------------------------------------------------

    def put(self, digest: str, mesh: Mesh) -> tuple[Mesh, int] | None:
        """Keep ``mesh`` (read from an upload whose SHA-256 is ``digest``): the mesh held
        (an earlier one of the same digest stays) and its bytes; None when there is no room
        now (the jobs in flight hold the budget).

        Raises
        ------
        TooLarge
            The mesh alone takes more than the capacity.
        """
        with self._lock:
            unit = self._units.get((digest,))
            if unit is not None:
                self._touch((digest,))
                return unit.value, unit.bytes
        mesh = owned(mesh)
        size = held_bytes(mesh)
        if size > self.capacity or not self.capacity:  # 0: the cache is off
            raise TooLarge(size, self.capacity)
        read_only(mesh)
        with self._lock:
            unit = self._units.get((digest,))
            if unit is not None:  # another request kept it meanwhile
                return unit.value, unit.bytes
            if not self._make_room(size, keep=()):
                return None
            self._add((digest,), _Unit(mesh, size))
        return mesh, size

    def get(self, digest: str) -> tuple[Mesh, int] | None:
        """The mesh of the upload whose SHA-256 is ``digest``, and its bytes, if held."""
        with self._lock:
            unit = self._units.get((digest,))
            if unit is None:
                return None
            self._touch((digest,))
            return unit.value, unit.bytes

    def mesh(self, digest: str) -> Mesh | None:
        held = self.get(digest)
        return None if held is None else held[0]

    def holds(self, owner: object) -> bool:
        with self._lock:
            return self._key_of(owner) is not None

    # -- what is computed from them ------------------------------------------------------

    def remember(
        self, ctx: Context, owner: object, key: Hashable, compute: Callable[[Context], T]
    ) -> T:
        """``compute`` 's result on ``owner`` for ``key``: kept, with its warnings, while
        ``owner`` is; computed (outside the lock: steps nest) and kept when it is not there
        yet; computed alone when ``owner`` is not held."""
        with self._lock:
            owner_key = self._key_of(owner)
            unit = None
            if owner_key is not None:
                unit = self._units.get((*owner_key, key))
                if unit is not None:
                    self._touch((*owner_key, key))
                    self._recount((*owner_key, key), unit)
        if owner_key is None:
            return compute(ctx)
        if unit is not None:
            MESH_CACHE_STEPS.labels("reused").inc()
            ctx.warnings.extend(unit.warnings)
            return unit.value
        MESH_CACHE_STEPS.labels("computed").inc()
        own = ctx.apart()
        value = compute(own)
        ctx.warnings.extend(own.warnings)
        self._keep((*owner_key, key), value, tuple(own.warnings))
        return value

    def _keep(self, key: Key, value: object, warnings: tuple[Warned, ...]) -> None:
        """Keep a step's result if its mesh is still held and there is room."""
        with self._lock:
            ancestors = tuple(key[:end] for end in range(1, len(key)))
            gone = not all(a in self._units for a in ancestors)
            if gone or key in self._units or id(value) in self._keys:
                return
            size = self._size(key, value)
            if not self._make_room(size, keep=ancestors):
                return
            read_only(value)
            self._add(key, _Unit(value, size, warnings))

    # -- room --------------------------------------------------------------------------

    def reclaim(self, nbytes: int) -> int:
        """Let go of the least recently used until ``nbytes`` are given back to the budget
        (a job needs them), or nothing is left; the bytes given back."""
        freed = 0
        with self._lock:
            while freed < nbytes and self._units:
                freed += self._evict(next(iter(self._units)))
        return freed

    def _make_room(self, size: int, keep: tuple[Key, ...]) -> bool:
        """Under the lock: room for ``size`` more bytes within the capacity and the budget,
        letting go of the least recently used but ``keep``; whether there is."""
        kept = sum(self._units[key].bytes for key in keep)
        if size + kept > self.capacity:
            return False
        while self.bytes + size > self.capacity:
            self._evict(self._oldest_but(keep))
        while self._budget is not None and not self._budget.take(size, reclaiming=False):
            if len(self._units) == len(keep):
                return False
            self._evict(self._oldest_but(keep))
        return True

    def _oldest_but(self, keep: tuple[Key, ...]) -> Key:
        return next(key for key in self._units if key not in keep)

    def _add(self, key: Key, unit: _Unit) -> None:
        """Under the lock: hold ``unit`` (its bytes already taken from the budget)."""
        self._units[key] = unit
        self._keys[id(unit.value)] = key
        self.bytes += unit.bytes
        MESH_CACHE_BYTES.inc(unit.bytes)
        self._touch(key)

    def _evict(self, key: Key) -> int:
        """Under the lock: let go of ``key`` and what was computed from it; the bytes given
        back."""
        freed = 0
        for gone in [k for k in self._units if k[: len(key)] == key]:
            unit = self._units.pop(gone)
            del self._keys[id(unit.value)]
            freed += unit.bytes
        self.bytes -= freed
        MESH_CACHE_BYTES.dec(freed)
        if self._budget is not None and freed:
            self._budget.give(freed)
        return freed

    def _touch(self, key: Key) -> None:
        """Under the lock: ``key`` and its owners become the most recently used (an owner
        after what was computed from it: it never goes first)."""
        for end in range(len(key), 0, -1):
            self._units.move_to_end(key[:end])

    def _recount(self, key: Key, unit: _Unit) -> None:
        """Under the lock: count what a result grew by since it was kept (a value computed
        once on first use, such as a map's triangle boxes); let go of it if that finds no
        room."""
        size = self._size(key, unit.value)
        growth = size - unit.bytes
        if growth <= 0:
            return
        fits = self.bytes + growth <= self.capacity
        if fits and (self._budget is None or self._budget.take(growth, reclaiming=False)):
            unit.bytes, self.bytes = size, self.bytes + growth
            MESH_CACHE_BYTES.inc(growth)
        else:
            self._evict(key)

    def _size(self, key: Key, value: object) -> int:
        """Under the lock: the bytes ``value`` holds beyond what its owners (the mesh, the
        result it was computed from) hold, which they count."""
        seen: set[int] = set()
        for end in range(1, len(key)):
            held_bytes(self._units[key[:end]].value, seen)
        return held_bytes(value, seen)

    def _key_of(self, owner: object) -> Key | None:
        key = self._keys.get(id(owner))
        if key is None or self._units[key].value is not owner:
            return None
        return key


class TooLarge(Exception):
    """A mesh that alone takes more than the cache's capacity."""

    def __init__(self, size: int, capacity: int) -> None:
        super().__init__(f"{size} bytes; the cache holds {capacity}")
        self.size, self.capacity = size, capacity


# -- what a value holds --------------------------------------------------------------------

_PLAIN = (str, bytes, int, float, complex, bool, type(None), enum.Enum, np.generic)


def arrays_of(value: object) -> Iterator[np.ndarray]:
    """Every numpy array ``value`` holds: through dataclasses (their fields and what a
    ``cached_property`` put in them), slots, dicts, lists and tuples, each object once."""
    seen: set[int] = set()
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, np.ndarray):
            yield item
            continue
        if isinstance(item, _PLAIN) or callable(item) or id(item) in seen:
            continue
        seen.add(id(item))
        if isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list | tuple | set | frozenset):
            stack.extend(item)
        else:
            if dataclasses.is_dataclass(item):
                stack.extend(getattr(item, f.name, None) for f in dataclasses.fields(item))
            stack.extend(getattr(item, "__dict__", {}).values())
            for name in getattr(type(item), "__slots__", ()):
                stack.append(getattr(item, name, None))


def _root(array: np.ndarray) -> np.ndarray:
    """The array that owns the memory ``array`` views (itself when it owns it)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array


def held_bytes(value: object, seen: set[int] | None = None) -> int:
    """The bytes of the arrays ``value`` holds, each block of memory once (a view counts its
    whole base); ``seen`` (ids of those blocks) leaves out what was counted already and
    gains what this counts."""
    seen = set() if seen is None else seen
    total = 0
    for array in arrays_of(value):
        root = _root(array)
        if id(root) not in seen:
            seen.add(id(root))
            total += root.nbytes
    return total


def read_only(value: object) -> None:
    """Make every array ``value`` holds read-only."""
    for array in arrays_of(value):
        array.flags.writeable = False


def _own(array: np.ndarray | None) -> np.ndarray | None:
    """``array``, or a copy of it where it views memory no array owns (a reader's view into
    the request body, which keeping would keep the whole body)."""
    if array is None or _root(array).base is None:
        return array
    return array.copy()


def owned(mesh: Mesh) -> Mesh:
    """``mesh`` with arrays that own their memory (see :func:`_own`)."""
    a = mesh.attributes
    attributes = Attributes(
        colors=_own(a.colors),
        uv=_own(a.uv),
        uv_faces=_own(a.uv_faces),
        vertex={name: _own(values) for name, values in a.vertex.items()},
        face={name: _own(values) for name, values in a.face.items()},
    )
    return dataclasses.replace(
        mesh,
        vertices=_own(mesh.vertices),
        faces=_own(mesh.faces),
        groups={name: _own(ranges) for name, ranges in mesh.groups.items()},
        attributes=attributes,
    )
