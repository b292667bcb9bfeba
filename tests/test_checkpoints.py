"""A long computation stops at its next checkpoint once its caller's check raises: the
transforms' loops pass checkpoints, a served job past its time limit stops at the first one
after it and frees its slot, and the checks of one job never reach another's."""

from __future__ import annotations

import json
import threading
import traceback

import anyio
import numpy as np
import pytest

from service.samples import SAMPLES
from service.server import jobs
from service.server.admission import job_gate
from service.settings import Settings
from transforms import fit_region, untangle
from transforms.checkpoints import checked, checkpoint
from transforms.registration import RegionScans, register, register_region
from transforms.sites import place_sites

from .conftest import load_sample, started
from .test_sites import jittered_mesh, whole
from .test_untangle import dragged_grid

pytestmark = pytest.mark.anyio


class Stop(Exception):
    pass


class Counted:
    """A check that counts its calls and raises :class:`Stop` at call ``stop_at`` (never
    without one)."""

    def __init__(self, stop_at: int | None = None) -> None:
        self.calls, self.stop_at = 0, stop_at

    def __call__(self) -> None:
        self.calls += 1
        if self.stop_at is not None and self.calls >= self.stop_at:
            raise Stop


def head():
    vertices, faces = load_sample("fsaverage-head.ply")
    return np.array(vertices), np.array(faces)


def fit_head():
    vertices, faces = head()
    return fit_region(vertices, faces[vertices[faces].mean(axis=1)[:, 2] > 0])


def register_head():
    vertices, faces = head()
    moved = vertices @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T + 5.0
    scans = RegionScans(moved, faces, vertices, faces, np.arange(len(faces)))
    whole = register(scans.follow, scans.base)
    return register_region(scans, whole)


def sites_on_grid():
    triangles = jittered_mesh(n=40, seed=3)
    part = whole(triangles, 3000)
    return place_sites(triangles.surface_points, triangles.faces, [part], np.random.default_rng(1))


def untangle_grid():
    vertices, faces, x, y = dragged_grid()
    return untangle(x, y, faces, vertices, 1)


LONG = {
    "fit": fit_head,
    "registration": register_head,
    "sites": sites_on_grid,
    "untangling": untangle_grid,
}


def test_a_checkpoint_without_a_check_does_nothing():
    assert checkpoint() is None


@pytest.mark.parametrize("name", LONG)
def test_a_long_computation_passes_checkpoints_and_stops_at_the_first_that_raises(name):
    passed = Counted()
    with checked(passed):
        LONG[name]()
    assert passed.calls >= 3  # its loops check, not only its start
    for stop_at in (1, passed.calls // 2):
        stopping = Counted(stop_at)
        with checked(stopping), pytest.raises(Stop):
            LONG[name]()
        assert stopping.calls == stop_at  # nothing ran on to another check
    assert checkpoint() is None  # the check ends with its block


def test_a_check_belongs_to_its_own_thread():
    seen = []

    def other() -> None:
        checkpoint()  # no check of its own: must not raise the main thread's
        seen.append(True)

    with checked(Counted(stop_at=1)):
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
    assert seen == [True]


async def test_a_job_past_its_time_limit_stops_at_its_next_checkpoint(monkeypatch):
    """A registration of two 17,670-face heads (Lee Perry-Smith) takes over a second; with a
    0.5 s limit its client has its 504, and the thread still computing stops at the first
    check after the limit (one call past it, the one that raises), in a loop of the core (the
    fit's or the registration's, as the machine's speed has it; not at the stage after it),
    so its slot is soon free."""
    expired_calls = []
    check = jobs.Deadline.check

    def recorded(deadline):
        if deadline.remaining() <= 0:  # where the check came from: a loop, or a stage
            expired_calls.append(traceback.extract_stack()[-3].filename)
        return check(deadline)

    monkeypatch.setattr(jobs.Deadline, "check", recorded)
    head = SAMPLES["lee-perry-smith.glb"].path.read_bytes()
    async with started(Settings(request_timeout=0.5)) as client:
        response = await client.post(
            "/v1/register",
            files={"baseline": ("b.glb", head), "follow_up": ("f.glb", head)},
            data={"params": json.dumps({})},
        )
        assert response.status_code == 504, response.text
        gate = job_gate(client._transport.app)
        for _ in range(600):
            if gate.in_flight == 0:
                break
            await anyio.sleep(0.05)
        assert gate.in_flight == 0, "the job still holds its slot"
    assert len(expired_calls) == 1 and "/transforms/" in expired_calls[0], expired_calls
