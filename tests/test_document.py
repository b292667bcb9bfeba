"""The OpenAPI document against the service: every route's answer conforms to the schema the
document gives it, every example sits under its own media type, and no reference dangles
(the models are derived from the capabilities, so none can be forgotten)."""

from __future__ import annotations

import json

import httpx
import pytest
from jsonschema import Draft202012Validator

from service.app import create_app
from service.capabilities import JSON_CAPABILITIES, MESH_CAPABILITIES
from service.capabilities.inputs import MeshPart
from service.document import check_references, referenced_models
from service.examples import icosahedron_obj, request_example
from service.settings import Settings

pytestmark = pytest.mark.anyio


@pytest.fixture(scope="module")
def app():
    return create_app(Settings())


@pytest.fixture(scope="module")
def document(app):
    return app.openapi()


@pytest.fixture
async def client(app):
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://meshflat") as c:
        yield c


def conforms(document: dict, path: str, status: str, media: str, body) -> None:
    """Assert that ``body`` is what the document says ``path`` answers with ``status``."""
    (operation,) = document["paths"][path].values()
    schema = operation["responses"][status]["content"][media]["schema"]
    # The schema's references point into the document's components.
    validator = Draft202012Validator({**schema, "components": document["components"]})
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in validator.iter_errors(body)]
    assert not errors, (path, status, errors[:5])


async def test_every_json_answer_conforms_to_its_documented_schema(client, document):
    mesh = icosahedron_obj()
    for capability in MESH_CAPABILITIES:
        params = json.dumps(request_example(capability.params))
        meshes = [part.name for part in capability.parts if isinstance(part, MeshPart)]
        files = {name: ("ico.obj", mesh) for name in meshes}
        answer = await client.post(capability.path, files=files, data={"params": params})
        assert answer.status_code == 200, answer.text
        conforms(document, capability.path, "200", "application/json", answer.json())
    for capability in JSON_CAPABILITIES:
        answer = await client.post(capability.path, json=request_example(capability.request))
        assert answer.status_code == 200, answer.text
        conforms(document, capability.path, "200", "application/json", answer.json())
    for path in ("/healthz", "/v1/samples"):
        answer = await client.get(path)
        conforms(document, path, "200", "application/json", answer.json())
    answer = await client.post(
        "/v1/flatten", files={"mesh": ("ico.obj", mesh)}, data={"params": '{"sigma": -1}'}
    )
    conforms(document, "/v1/flatten", "422", "application/problem+json", answer.json())


async def test_a_mercator_answer_and_a_miss_conform_too(client, document):
    """The optional parts: x and y per vertex, and a null hit."""
    mesh = icosahedron_obj()
    example = request_example(MESH_CAPABILITIES[0].params)
    answer = await client.post(
        "/v1/flatten",
        files={"mesh": ("ico.obj", mesh)},
        data={"params": json.dumps({**example, "layout": "mercator"})},
    )
    assert "x" in answer.json()["vertices"]
    conforms(document, "/v1/flatten", "200", "application/json", answer.json())
    miss = {**example, "theta": [0.0], "phi": [0.0]}  # a singular point's direction
    answer = await client.post(
        "/v1/locate", files={"mesh": ("ico.obj", mesh)}, data={"params": json.dumps(miss)}
    )
    assert answer.json()["hits"] == [None]
    conforms(document, "/v1/locate", "200", "application/json", answer.json())


def test_no_reference_dangles_and_every_request_model_is_a_component(document):
    assert check_references(document) == []
    components = document["components"]["schemas"]
    for model in referenced_models():
        assert model.__name__ in components


def test_a_forgotten_component_would_be_caught(document):
    broken = json.loads(json.dumps(document))
    del broken["components"]["schemas"]["LocateParams"]
    assert check_references(broken) == ["LocateParams"]


def test_examples_sit_under_their_own_media_type_only(document):
    for path, operations in document["paths"].items():
        for operation in operations.values():
            for status, response in operation["responses"].items():
                for media, content in response.get("content", {}).items():
                    if "example" not in content:
                        continue
                    expected = "application/problem+json" if status[0] in "45" else None
                    if expected:
                        assert media == expected, (path, status, media)
                    else:
                        assert media == "application/json", (path, status, media)


def test_every_route_has_a_computed_200_example(document):
    for capability in (*MESH_CAPABILITIES, *JSON_CAPABILITIES):
        (operation,) = document["paths"][capability.path].values()
        content = operation["responses"]["200"]["content"]["application/json"]
        assert "example" in content, capability.path
