"""Nothing of an uploaded mesh reaches the disk or the logs, and an unexpected failure is a
500 problem that says nothing of the request."""

from __future__ import annotations

import os
import sys
import tempfile

import pytest

from service.capabilities.region import resolve

from .test_api import flatten, problem

pytestmark = pytest.mark.anyio

#: A marker to look for: a group name in the uploaded file, a word in an exception.
SECRET = "patient-7f3a9c"
OBJ = f"g {SECRET}\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\nf 1 2 3\nf 2 4 3\n".encode()

_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND
_writes: list[tuple] | None = None


def _on_audit(event: str, args: tuple) -> None:
    # Audit hooks cannot be removed: this one records only while a test sets _writes.
    if _writes is None:
        return
    if event == "open":
        path, mode, flags = args
        writing = (
            any(c in mode for c in "wax+") if isinstance(mode, str) else bool(flags & _WRITE_FLAGS)
        )
        if writing and "__pycache__" not in str(path):  # bytecode of a first import
            _writes.append((event, path))
    elif event in ("tempfile.mkstemp", "tempfile.mkdtemp", "os.mkdir"):
        _writes.append((event, args[0]))


sys.addaudithook(_on_audit)


async def watched_writes(call) -> list[tuple]:
    global _writes
    _writes = []
    try:
        await call()
        return _writes
    finally:
        _writes = None


async def test_a_flatten_opens_no_file_for_writing(client):
    for name in ("nefertiti-lowres.obj", "lee-perry-smith.glb", "fsaverage-head.ply"):
        await flatten(client, name, {})  # first: imports done, caches filled

        async def flatten_once(name=name):
            assert (await flatten(client, name, {})).status_code == 200

        assert await watched_writes(flatten_once) == [], name


async def test_the_watch_sees_a_temporary_file():
    """The check above can fail: a spooled upload, as Starlette's form parser makes, shows."""

    async def spool():
        with tempfile.TemporaryFile() as spooled:
            spooled.write(OBJ)

    assert await watched_writes(spool)


async def test_the_logs_hold_nothing_of_a_mesh(client, caplog, capfd):
    with caplog.at_level("DEBUG"):
        await flatten(client, "x", {}, data=OBJ, filename="a.obj")
        unknown = await flatten(client, "x", {"region": {"groups": ["left"]}}, OBJ, "a.obj")
        assert SECRET in problem(unknown, 422)["detail"]  # told to the client only
        await flatten(client, "x", {}, data=OBJ + b"f 1 2 99\n", filename="a.obj")
    out, err = capfd.readouterr()
    assert SECRET not in caplog.text + out + err


async def test_an_unexpected_failure_is_a_bare_500(client, caplog, capfd, monkeypatch):
    def fail(*args, **kwargs):
        raise RuntimeError(f"the mesh of {SECRET} broke something")

    monkeypatch.setattr(resolve, "select_region", fail)
    with caplog.at_level("DEBUG"):
        response = await flatten(client, "x", {}, data=OBJ, filename="a.obj")
    body = problem(response, 500)
    assert SECRET not in response.text and "failed unexpectedly" in body["detail"]
    out, err = capfd.readouterr()
    assert SECRET not in caplog.text + out + err
    assert "unexpected RuntimeError on POST /v1/flatten" in caplog.text
    assert (await client.get("/healthz")).status_code == 200
