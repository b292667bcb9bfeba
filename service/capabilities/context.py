"""What a use-case is given beside its input: the settings, the memory budget it charges, the
threads it may use and the warnings it adds to its answer; and the memory model it charges by.

A use-case charges what a step will allocate before it allocates it (a picture's raster, a
map's triangles, sites), so that no mix of valid requests takes a worker past its budget.
In a served request the budget is the job's admission ticket (:mod:`service.server.jobs`),
whose charge may refuse (503 when the process has no room now, 413 when the job could never
fit): that refusal is the server's, and passes through the use-case untouched. On the command
line nothing is charged.

A served job may also find what it computes kept from an earlier request on the same mesh
(:class:`MeshStore`, the server's cache of meshes sent once): a step asks
:meth:`Context.remembered` for it, and computes it only when it is not there.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Protocol, TypeVar

from ..settings import Settings
from .warnings import Warned, WarningCode

if TYPE_CHECKING:
    from ..meshio import Mesh

T = TypeVar("T")

MiB = 2**20
#: What a reader may allocate per byte of its file beside its mesh (the readers keep within
#: it: see tests/test_meshio.py), charged when the body is in, on top of the body itself.
READER_BYTES_PER_BYTE = 7
#: What parsing a JSON body may take per byte (pydantic's objects, then the arrays): about
#: 20 measured for a /v1/points body, with room.
JSON_BYTES_PER_BYTE = 32
#: A computation's memory, an upper bound measured by ``make attack`` (docs/benchmarks.md):
#: a constant plus bytes per vertex and per face of the mesh; a picture (SVG or PNG) adds its
#: own raster, per pixel and per face.
JOB_BASE_BYTES = 64 * MiB
JOB_BYTES_PER_VERTEX = 200
JOB_BYTES_PER_FACE = 700
PICTURE_BASE_BYTES = 128 * MiB
PICTURE_BYTES_PER_PIXEL = 24
PICTURE_BYTES_PER_FACE = 400
#: What the map's triangles and the measuring of one zone add per region face (/v1/measure,
#: /v1/locate via the map): 308 at the peak of building them and 66 for a zone over most of a
#: million-face map, measured with tracemalloc, with room.
MAP_BYTES_PER_FACE = 450
#: What a zone's ring point costs wherever zones are covered (/v1/measure, /v1/sites): its
#: piece paired with the triangles of its cells (some 26), clipped and kept with the cover,
#: and the shares' terms of those pairs at their peak; 8.2 to 8.9 KB measured (tracemalloc
#: and peak RSS, rings of 5,000 to 50,000 points on 1.5k- and 24k-face scalps), with room
#: for a ring over the map's denser middle, where a cell holds a third more triangles.
ZONE_BYTES_PER_POINT = 12_000
#: What a curve's crossing of a triangle edge costs in /v1/measure: its runs and lifted
#: point, its part of the answer and a share of the trace (a block of pieces at a time, see
#: :func:`transforms.lift_curve`); about 560 bytes measured (tracemalloc, zig-zags over 1.5k-
#: and 24k-face scalps), charged for each crossing :func:`transforms.curve_crossings` counts
#: (1.1 to 2.6 times as many as there are on scalps).
CURVE_BYTES_PER_CROSSING = 800
#: What placing a site may take: its candidates and trees while placing, its values and their
#: JSON after (about 330 bytes of JSON a site).
SITE_BYTES = 2_000
#: What a growth field takes (docs/math.md, section 19): its grid's solve, a fixed size; and
#: per site its directions, their pushing forward and the pairs its smoothness is measured on.
GROWTH_BYTES = 256 * 2**20
GROWTH_BYTES_PER_SITE = 2_000


def job_bytes(vertices: int, faces: int) -> int:
    """The memory a computation on a mesh of that size may take (an upper bound)."""
    return JOB_BASE_BYTES + JOB_BYTES_PER_VERTEX * vertices + JOB_BYTES_PER_FACE * faces


def picture_bytes(width: int, height: int, faces: int) -> int:
    """What drawing a picture of ``width`` x ``height`` pixels of ``faces`` faces adds."""
    return (
        PICTURE_BASE_BYTES
        + PICTURE_BYTES_PER_PIXEL * width * height
        + (PICTURE_BYTES_PER_FACE * faces)
    )


class Budget(Protocol):
    """Memory a job may hold."""

    def charge(self, nbytes: int) -> None:
        """Hold ``nbytes`` more, or raise the problem that says there is no room."""

    def charge_mesh(self, nbytes: int) -> None:
        """Hold ``nbytes`` for the job's mesh, or the growth over what an earlier count of
        the same mesh held."""


class Unlimited:
    """No budget: the command line and the examples of the OpenAPI document."""

    def charge(self, nbytes: int) -> None:
        pass

    def charge_mesh(self, nbytes: int) -> None:
        pass


class MeshStore(Protocol):
    """Meshes sent once and what was computed from them (the server's
    :class:`service.meshcache.MeshCache`)."""

    def mesh(self, digest: str) -> Mesh | None:
        """The mesh whose upload had the SHA-256 ``digest`` (hex), if it is held."""

    def holds(self, owner: object) -> bool:
        """Whether ``owner`` is a held mesh or a value remembered of one."""

    def remember(
        self, ctx: Context, owner: object, key: Hashable, compute: Callable[[Context], T]
    ) -> T:
        """What ``compute(ctx)`` gives for ``owner`` and ``key``, computed once while held."""


@dataclass(frozen=True)
class Context:
    """The settings, the memory budget and the threads of one computation.

    Attributes
    ----------
    settings : Settings, the limits the use-case enforces (MESHFLAT_MAX_POINTS, ...)
    budget : Budget, what the use-case charges its allocations to
    warnings : list of Warned, what the use-case found legal but probably wrong, in the
        order found (:meth:`warn`); the JSON answer carries them
    meshes : MeshStore or None, the server's meshes sent once (None on the command line)
    """

    settings: Settings = field(default_factory=Settings)
    budget: Budget = field(default_factory=Unlimited)
    warnings: list[Warned] = field(default_factory=list)
    meshes: MeshStore | None = None

    def remembered(self, owner: object, key: Hashable, compute: Callable[[Context], T]) -> T:
        """``compute(ctx)``: a step's result on ``owner`` (a mesh, or a step's result on one)
        for the inputs ``key`` stands for. Where ``owner`` is held by the mesh cache, it is
        computed once and kept with it, with the warnings it added (added again on each use);
        elsewhere it is computed now."""
        if self.meshes is None:
            return compute(self)
        return self.meshes.remember(self, owner, key, compute)

    def holds(self, owner: object) -> bool:
        """Whether what is computed on ``owner`` is kept (:meth:`remembered`)."""
        return self.meshes is not None and self.meshes.holds(owner)

    def apart(self) -> Context:
        """This context with a list of warnings of its own (a step whose warnings are kept)."""
        return replace(self, warnings=[])

    def warn(self, code: WarningCode, field: str, message: str) -> None:
        """Add a warning to the answer: ``code`` (one of :class:`WarningCode`), the
        parameter it concerns (dotted as an error's field: ``units``, ``zones.2``) and what
        looks wrong, in plain words with the numbers."""
        self.warnings.append(Warned(code, field, message))

    @property
    def threads(self) -> int:
        """Threads the core may use (MESHFLAT_THREADS)."""
        return self.settings.threads

    def charge(self, nbytes: int) -> None:
        """Charge ``nbytes`` to the budget before they are allocated."""
        self.budget.charge(nbytes)

    def charge_mesh(self, vertices: int, faces: int) -> None:
        """Charge what computing on the job's mesh of that size may take (:func:`job_bytes`),
        once its reader has counted it and before it builds the arrays; a second count of the
        same mesh charges only the growth."""
        self.budget.charge_mesh(job_bytes(vertices, faces))

    def charge_other_mesh(self, vertices: int, faces: int) -> None:
        """Charge a second mesh of the job (a follow-up scan) on top of the first."""
        self.budget.charge(job_bytes(vertices, faces))
