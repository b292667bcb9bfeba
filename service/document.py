"""The OpenAPI document: FastAPI's, with the request bodies the routes read themselves, the
models they refer to (derived from :mod:`service.capabilities`, so none can be forgotten),
the API keys, and examples computed by the service (:mod:`service.examples`)."""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from pydantic import BaseModel
from pydantic.json_schema import models_json_schema

from . import heldmeshes
from .capabilities import JSON_CAPABILITIES, MESH_CAPABILITIES, MeshCapability
from .capabilities.inputs import MeshPart
from .meshio import reading_rules
from .problems import PROBLEMS, ProblemDetails
from .server.auth import PROTECTED_PREFIX

DESCRIPTION = """
meshflat flattens a region of a 3D mesh into distorted-pole spherical coordinates: the poles
and the seam of ordinary spherical coordinates are moved by a Moebius "pole warp" into a cap
of angle `rho = 2 atan(sigma)` around the local +Y axis, so a region outside that cap maps to
one seam-free patch.

Angles follow eq. 1 of the paper throughout: `theta` is the polar angle from local +Z in
[0, pi], `phi` the azimuth from +X towards +Y in (-pi, pi], in the local frame
`q = R (p - c)`. The paper's "alternative approach" section swaps these two names; meshflat
does not. The paper's printed eq. 2 is not the inverse of eq. 1; meshflat uses the true one.

Every error is `application/problem+json` (RFC 9457) whose `detail` names the field, the face
or vertex, and the limit.
"""


#: What the route's own mesh part adds to its description.
HELD = (
    " Required unless params.mesh_sha256 names a mesh sent to POST /v1/meshes instead (not both)."
)


def json_body(model: type[BaseModel]) -> dict:
    """The OpenAPI request body of a route that reads ``model`` as JSON itself."""
    schema = {"$ref": f"#/components/schemas/{model.__name__}"}
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": schema}}}}


def multipart_body(capability: MeshCapability) -> dict:
    """The OpenAPI request body of a mesh route: its ``params`` field and its parts."""
    model = capability.params
    name = model.__name__
    example = model.model_config["json_schema_extra"]["examples"][0]
    # An object part sent as JSON (the encoding below): clients and generators that read the
    # document build it from the schema itself.
    params = {
        "$ref": f"#/components/schemas/{name}",
        "description": f"JSON, as the {name} schema; default {{}}.",
        "example": example,
    }
    parts = {
        part.name: {
            "type": "string",
            "format": "binary",
            "description": part.documented + (HELD if part is capability.mesh else ""),
        }
        for part in capability.parts
    }
    # Every mesh part is read (a missing one is refused), but the route's own may be one held
    # instead (params.mesh_sha256); the PNG parts may be left out.
    required = [
        part.name
        for part in capability.parts
        if isinstance(part, MeshPart) and part is not capability.mesh
    ]
    form = {
        "schema": {
            "type": "object",
            "required": required,
            "properties": {"params": params, **parts},
            "additionalProperties": False,  # a part the route does not read is refused
        },
        "encoding": {"params": {"contentType": "application/json"}},
    }
    return {"requestBody": {"required": True, "content": {"multipart/form-data": form}}}


ARROW_RULES = """
Every mesh route also answers its JSON as an Arrow IPC stream
(`application/vnd.apache.arrow.stream`, by `Accept` or `params.output`: `arrow`), which
Arrow JS and pyarrow read into typed arrays without parsing text: one record batch of one
row. Each array of numbers of the JSON answer is a column named by its dotted path
(`vertices.x`, `faces.vertices`, `zones.0.partial_faces`), a list holding exactly the JSON's
numbers: an array of numbers as a list of them, an array of rows of `k` numbers as a list of
fixed-size lists of `k` (of `p` rows of `k`: fixed-size lists of `p` such lists); integers
as int32 (int64 for an array with a value beyond int32), floats as float64 bit for bit, null
where the JSON has null. The rest of
the answer, the same JSON without those arrays, is the schema's metadata `meshflat`.
`/v1/locate`'s hits, an object of numbers a query, are a column a field (`hits.face`,
`hits.barycentric`, `hits.point`), null where the JSON's hit is null. Strings, other objects
and empty or null arrays stay in the metadata.
"""


def mesh_description(capability: MeshCapability) -> str:
    """A mesh route's description, ending with its Arrow form and how files are read."""
    return f"{capability.description}\n{ARROW_RULES}\n{reading_rules()}"


def other_forms(capability: MeshCapability) -> dict:
    """The answers of a mesh route besides its JSON: the other media types of its 200, and
    the 406 for an ``Accept`` that allows none."""
    others = capability.outputs[1:]
    if not others:
        return {}
    content = {
        output.media_type: {
            "schema": {"type": "string", "format": "binary"}
            if output.binary
            else {"type": "string"}
        }
        for output in others
    }
    refusal = f"Accept allows none of the forms {capability.path} answers."
    return {
        200: {"content": content, "description": "The answer, in the form asked for."},
        406: PROBLEMS[422] | {"description": refusal},
    }


def referenced_models() -> list[type[BaseModel]]:
    """The models the hand-made request bodies refer to, and the problem details."""
    models = [c.params for c in MESH_CAPABILITIES] + [c.request for c in JSON_CAPABILITIES]
    return [*dict.fromkeys(models), *heldmeshes.MODELS, ProblemDetails]


def build(app: FastAPI) -> dict:
    """The app's OpenAPI document (cached on the app)."""
    if app.openapi_schema is None:
        document = get_openapi(
            title=app.title,
            version=app.version,
            summary=app.summary,
            description=app.description,
            routes=app.routes,
        )
        _, definitions = models_json_schema(
            [
                (model, "serialization" if model is ProblemDetails else "validation")
                for model in referenced_models()
            ],
            ref_template="#/components/schemas/{model}",
        )
        document.setdefault("components", {}).setdefault("schemas", {}).update(
            definitions.get("$defs", {})
        )
        from .examples import add_examples  # they run the service's own code

        app.openapi_schema = add_examples(_declare_keys(document))
    return app.openapi_schema


def _declare_keys(document: dict) -> dict:
    """The two ways to send an API key, required by every ``/v1`` operation (they are
    checked only when the service has keys: service.server.auth)."""
    document["components"]["securitySchemes"] = {
        "bearer": {"type": "http", "scheme": "bearer", "description": "An API key."},
        "apiKey": {"type": "apiKey", "in": "header", "name": "X-API-Key"},
    }
    for path, operations in document["paths"].items():
        if path.startswith(PROTECTED_PREFIX):
            for operation in operations.values():
                operation["security"] = [{"bearer": []}, {"apiKey": []}]
    return document


def check_references(document: dict) -> list[str]:
    """The ``$ref`` targets the document names but does not define (none, when it is
    whole)."""
    defined = set(document.get("components", {}).get("schemas", {}))
    missing: set[str] = set()

    def walk(value) -> None:
        if isinstance(value, dict):
            ref = value.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/components/schemas/"):
                name = ref.rsplit("/", 1)[-1]
                if name not in defined:
                    missing.add(name)
            for item in value.values():
                walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)

    walk(document)
    return sorted(missing)
