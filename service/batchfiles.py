"""The files of ``meshflat batch``, confined: a scan's mesh read only from inside the
manifest's folder (or an ``--allow-root``), a regular file within the upload limit, and its
outputs written only into its own folder under ``--out``, never through a symbolic link.

A mesh path is resolved and must stay inside a root; its last component is opened with
``O_NOFOLLOW`` (and ``O_NONBLOCK``: a FIFO's open does not wait for a writer), and what was
opened must be the resolved file, a regular one (no FIFO, device or directory) of at most
``max_bytes``, checked with ``fstat`` before a byte is read. A scan's folder is opened with
``O_NOFOLLOW`` (a symbolic link at ``DIR/NAME`` is refused) and every file in it is opened
relative to it, with ``O_NOFOLLOW``; a temporary ``.partial`` file is created with
``O_EXCL`` after whatever was at its name (a planted link included) is removed.

A reader's message may quote the file (a PLY header line, a property's name): what the batch
logs and writes of it is :func:`content_free`, the error's kind and its position only; a
use-case's refusal may name what the file has (its groups, its vertex properties), and
:func:`quoting_only` shows every quoted word the manifest's line did not give as ``'…'``.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

from .meshio.mesh import MeshFormatError, MeshTooLargeError
from .problems import Problem

_READ = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
#: A position a reader's message gives (before anything it quotes): a line or a byte.
_POSITION = re.compile(r"\b(line|byte|row|face|vertex) (\d+)\b")


def _refused(path: str, why: str, status: int = 422, kind: str = "invalid-request") -> Problem:
    return Problem(status, f"mesh: {path!r} {why}", kind, field="mesh")


def inside(path: Path, roots: tuple[Path, ...]) -> bool:
    """Whether ``path`` (resolved) lies in one of ``roots`` (resolved)."""
    return any(path.is_relative_to(root) for root in roots)


def read_confined(path: Path, roots: tuple[Path, ...], max_bytes: int) -> bytes:
    """The bytes of the mesh at ``path``, which must resolve inside one of ``roots`` and be a
    regular file of at most ``max_bytes``.

    Raises
    ------
    Problem
        Outside the roots, not a regular file, a symbolic link, too large, or unreadable
        (naming the path as given, never its content).
    """
    shown = str(path)
    resolved = Path(os.path.realpath(path))
    if not inside(resolved, tuple(Path(os.path.realpath(root)) for root in roots)):
        raise _refused(shown, "lies outside the manifest's folder (and any --allow-root)")
    try:
        descriptor = os.open(path, _READ)
    except OSError as error:
        if os.path.islink(path):
            raise _refused(shown, "is a symbolic link; name the file itself") from None
        raise Problem(422, f"mesh: cannot read {shown!r}: {error.strerror}", field="mesh") from None
    try:
        found = os.fstat(descriptor)
        if not stat.S_ISREG(found.st_mode):
            raise _refused(shown, "is not a regular file (a FIFO, device or folder)")
        if not os.path.samestat(found, os.stat(resolved)):
            raise _refused(shown, "changed while it was opened")
        if found.st_size > max_bytes:
            raise _too_large(shown, max_bytes)
        os.set_blocking(descriptor, True)
        chunks, total = [], 0
        while chunk := os.read(descriptor, min(1 << 20, max_bytes + 1 - total)):
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise _too_large(shown, max_bytes)
        return b"".join(chunks)
    except OSError as error:
        raise Problem(422, f"mesh: cannot read {shown!r}: {error.strerror}", field="mesh") from None
    finally:
        os.close(descriptor)


def _too_large(shown: str, max_bytes: int) -> Problem:
    return _refused(
        shown,
        f"is larger than {max_bytes} bytes, the upload limit (MESHFLAT_MAX_UPLOAD_BYTES)",
        413,
        "mesh-too-large",
    )


def content_free(error: MeshFormatError, part: str) -> Problem:
    """A reader's refusal without its message (which may quote the file): its kind, and the
    line or byte it names, if it names one before anything it quotes."""
    message = str(error)
    unquoted = re.split(r"['\"]", message, maxsplit=1)[0]
    position = _POSITION.search(unquoted)
    at = f" at {position[1]} {position[2]}" if position else ""
    kind = type(error).__name__
    if isinstance(error, MeshTooLargeError):
        detail = f"{part}: beyond a limit of the settings ({kind}{at})"
        return Problem(413, detail, "mesh-too-large", part)
    detail = f"{part}: not a readable mesh ({kind}{at}; the file's content is not repeated)"
    return Problem(422, detail, "unreadable-mesh", part)


#: A quoted piece of a message, as ``repr`` quotes a string (not an apostrophe: a word's).
_QUOTED = re.compile(r"(?<!\w)('(?:[^'\\]|\\.)*'|\"(?:[^\"\\]|\\.)*\")(?!\w)")


def words_of(value) -> set[str]:
    """Every string in ``value`` (a manifest line's params: keys and values, nested)."""
    if isinstance(value, str):
        return {value}
    if isinstance(value, dict):
        return set().union(*(words_of(k) | words_of(v) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return set().union(*(words_of(item) for item in value))
    return set()


def quoting_only(problem: Problem, given: set[str]) -> Problem:
    """``problem`` with every quoted word that is not one of ``given`` (what the manifest's
    line says) shown as ``'…'``: a use-case's refusal may name what the file has (its
    groups, its vertex properties), which is the file's content."""

    def shown(match: re.Match) -> str:
        return match[0] if match[0][1:-1] in given else "'…'"

    detail = _QUOTED.sub(shown, problem.detail)
    if detail == problem.detail:
        return problem
    return Problem(problem.status, detail, problem.kind, problem.field, problem.indices)


class ScanFolder:
    """``DIR/NAME``, made if missing and opened without following a link: every file in it
    is read and written relative to it, never through a symbolic link.

    Raises
    ------
    OSError
        The folder cannot be made or opened (a symbolic link at ``DIR/NAME`` included).
    """

    def __init__(self, out: Path, name: str, create: bool = True) -> None:
        self.path = out / name
        parent = os.open(out, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            if create:
                try:
                    os.mkdir(name, dir_fd=parent)
                except FileExistsError:
                    pass
            flags = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
            self.fd = os.open(name, flags, dir_fd=parent)
        finally:
            os.close(parent)

    def close(self) -> None:
        os.close(self.fd)

    def __enter__(self) -> ScanFolder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def read(self, name: str) -> bytes:
        """A regular file of the folder (not a link)."""
        descriptor = os.open(name, _READ, dir_fd=self.fd)
        try:
            if not stat.S_ISREG(os.fstat(descriptor).st_mode):
                raise IsADirectoryError(name)
            os.set_blocking(descriptor, True)
            with os.fdopen(descriptor, "rb", closefd=False) as file:
                return file.read()
        finally:
            os.close(descriptor)

    def unlink(self, name: str) -> None:
        """Remove ``name`` (a link itself, not what it points to), if it is there."""
        try:
            os.unlink(name, dir_fd=self.fd)
        except FileNotFoundError:
            pass

    def write_partial(self, name: str, data: bytes) -> None:
        """``data`` into ``.NAME.partial``, created anew (``O_EXCL``, ``O_NOFOLLOW``)."""
        partial = partial_name(name)
        self.unlink(partial)
        descriptor = os.open(partial, _CREATE, 0o666, dir_fd=self.fd)
        with os.fdopen(descriptor, "wb") as file:
            file.write(data)

    def commit(self, name: str) -> None:
        """``.NAME.partial`` renamed to ``NAME`` (replacing whatever is there, a link itself
        included, never what it points to)."""
        os.replace(partial_name(name), name, src_dir_fd=self.fd, dst_dir_fd=self.fd)

    def write_atomically(self, name: str, data: bytes) -> None:
        self.write_partial(name, data)
        self.commit(name)


def partial_name(name: str) -> str:
    return f".{name}.partial"
