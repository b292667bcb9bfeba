"""The HTTP service, through httpx against the ASGI app."""

import json

import httpx
import pytest

from service.app import app
from service.openapi import DOCUMENT, render


@pytest.fixture
async def client():
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as c:
        yield c


def test_committed_openapi_document_is_current():
    """Regenerate with `python -m service.openapi` when the API changes."""
    assert json.loads(DOCUMENT.read_text()) == json.loads(render())


@pytest.mark.anyio
async def test_start_up_flattens_a_bundled_scan_and_logs_it(caplog, client):
    with caplog.at_level("INFO", logger="meshflat"):
        async with app.router.lifespan_context(app):
            assert (await client.get("/healthz")).status_code == 200
    messages = [r.getMessage() for r in caplog.records if r.name == "meshflat"]
    assert any("self-check: scalp of fsaverage-head.ply" in m for m in messages)
    assert any("flattened seam-free" in m for m in messages)


def test_self_check_result():
    from service.selfcheck import run_self_check

    check = run_self_check()
    assert check.ok and check.faces > 1000 and check.margin_deg > 10.0


def test_allocator_keeps_large_blocks_on_glibc():
    from service.allocator import keep_large_blocks

    assert keep_large_blocks()  # the machines meshflat runs on use glibc
