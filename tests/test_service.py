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


def without_example_numbers(node, in_example: bool = False):
    """``node`` (a JSON value) with each number inside an ``example`` or ``examples`` replaced
    by its type's name: the examples are computed live (a fit's numbers follow the machine's
    floating point through its linear program), the rest of the document is exact."""
    if isinstance(node, dict):
        return {
            key: without_example_numbers(value, in_example or key in ("example", "examples"))
            for key, value in node.items()
        }
    if isinstance(node, list):
        return [without_example_numbers(value, in_example) for value in node]
    if in_example and isinstance(node, int | float) and not isinstance(node, bool):
        return type(node).__name__
    return node


def test_committed_openapi_document_is_current():
    """Regenerate with `python -m service.openapi` when the API changes: the routes, fields,
    types, descriptions and the examples' shapes and words; not the examples' numbers."""
    committed = without_example_numbers(json.loads(DOCUMENT.read_text()))
    assert committed == without_example_numbers(json.loads(render()))


def test_the_document_check_sees_a_changed_field_but_not_an_example_number():
    """The comparison above still catches drift: a renamed field fails it."""
    document = json.loads(render())
    changed = json.loads(json.dumps(document).replace('"center_depth"', '"centre_depth"'))
    assert without_example_numbers(changed) != without_example_numbers(document)
    path = document["paths"]["/v1/fit"]["post"]["responses"]["200"]["content"]
    example = path["application/json"]["example"]
    example["explain"]["center_depth"] = example["explain"]["center_depth"] * 1.5 + 1.0
    assert without_example_numbers(document) == without_example_numbers(json.loads(render()))


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
    # It quotes the trusted median and p95 (a mean is set by a few slivers) and the flagged.
    quoted = f"isometric energy p50 {check.isometric_p50:.3f}, p95 {check.isometric_p95:.3f}"
    assert quoted in str(check) and "flagged)" in str(check)
    assert 1.0 <= check.isometric_p50 <= check.isometric_p95 < 2.0


def test_allocator_keeps_large_blocks_on_glibc():
    from service.server.allocator import keep_large_blocks

    assert keep_large_blocks()  # the machines meshflat runs on use glibc


@pytest.mark.parametrize(("given", "expected"), [(None, 1), ("2", 2)])
def test_service_runs_blas_on_one_thread_unless_told(given, expected):
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    # A fresh interpreter, asking the OpenBLAS numpy loaded how many threads it runs (the
    # setting only counts when made before numpy loads).
    code = (
        "import ctypes, glob, os, service.app, numpy;"
        "libs = os.path.join(os.path.dirname(numpy.__file__), os.pardir, 'numpy.libs');"
        "blas = ctypes.CDLL(glob.glob(os.path.join(libs, 'libscipy_openblas*'))[0]);"
        "print(blas.scipy_openblas_get_num_threads64_())"
    )
    found = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert int(found.stdout) == expected
