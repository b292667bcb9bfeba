"""Every case of the malformed-input corpus (tests/corpus.py) gets its status and a problem
whose detail names the cause; none is a 500, and the service answers normally afterwards."""

from __future__ import annotations

import json

import httpx
import pytest

from service.app import create_app
from service.settings import Settings

from .corpus import UPLOAD_LIMIT, Case, cases
from .test_api import problem

pytestmark = pytest.mark.anyio
CASES = cases()


def test_the_corpus_has_at_least_40_cases_with_distinct_names():
    assert len(CASES) >= 40
    assert len({case.name for case in CASES}) == len(CASES)


@pytest.fixture(scope="module")
async def corpus_client():
    app = create_app(Settings(max_upload_bytes=UPLOAD_LIMIT))
    async with app.router.lifespan_context(app):
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://m") as c:
            yield c


@pytest.fixture(scope="module")
def anyio_backend():
    return "asyncio"


async def send(client: httpx.AsyncClient, case: Case) -> httpx.Response:
    if case.mesh is not None:
        params = case.params if isinstance(case.params, str) else json.dumps(case.params or {})
        return await client.post(
            case.route, files={"mesh": case.mesh}, data={"params": params}, headers=case.headers
        )
    headers = {"content-type": case.content_type} | case.headers
    return await client.post(case.route, content=case.body, headers=headers)


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
async def test_malformed_input_is_refused_with_its_cause_named(corpus_client, case):
    response = await send(corpus_client, case)
    body = problem(response, case.status)
    for words in case.detail:
        assert words in body["detail"], (case.name, body["detail"])
    assert (await corpus_client.get("/healthz")).status_code == 200
