"""Property-based requests generated from the OpenAPI document (schemathesis), sent in-process
to the app as deployed (with API keys), multipart routes included: every answer must be
documented (status, content type, headers), conform to its schema, and never be a server
error, whatever the request holds; all of schemathesis's checks run.

CI (HYPOTHESIS_PROFILE=ci) sends at least 2,000 requests; a longer run:

    MESHFLAT_FUZZ_EXAMPLES=2000 HYPOTHESIS_PROFILE=ci pytest tests/test_schema_fuzz.py
"""

from __future__ import annotations

import os

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from jsonschema import Draft202012Validator
from schemathesis.config import SchemathesisConfig
from schemathesis.core.parameters import ParameterLocation
from schemathesis.specs.openapi.checks import negative_data_rejection

from service.app import create_app
from service.samples import SAMPLES
from service.settings import Settings

from .conftest import slow

# test_ci_sends_enough_generated_requests counts what the fuzzing sent in its process: under
# pytest-xdist the module's tests run on one worker, in order.
pytestmark = [slow, pytest.mark.xdist_group("schema-fuzz")]

#: The service as deployed: with keys, so that the document's security is checked too (a
#: request without the key must get a 401).
KEY = "fuzz-key"
#: Sites capped low: the schema allows a million of them, which take seconds each request.
app = create_app(Settings(api_keys=(KEY,), max_sites=20_000))

# A request the schema allows must be accepted (2xx), with one exception, per route: the
# routes below also answer 422 to conditions a JSON schema cannot state: a mesh file's
# content (the schema says "binary"), a point at the centre (no direction), theta, phi and r
# of different lengths, "sigma or pole_angle_deg, not both" across a nested object, a ring
# drawn on the map that crosses itself or a hole outside its zone (and for /v1/plan, zones
# that overlap, a mix of hairs whose shares do not sum to 1). Their 422
# is still checked to be a documented problem that conforms to its schema. /v1/sites (and
# /v1/strands, which takes its params and needs a growth field and a length) also
# answers 422 to zones that overlap, a density without units or a spacing the sites do not
# fit at, and 413 to more sites than the limit; /v1/register 422 to a follow-up that cannot
# be read or registered; /v1/transfer 422 to an image part that is not a PNG of the
# picture's size, an image and values together, values not one a vertex, or nothing to carry.
# Every mesh route answers 404 to a params.mesh_sha256 the worker does not hold (a generated
# one never is), and /v1/meshes 422 to a file that is not the mesh its format names.
CONFIG = SchemathesisConfig.from_dict(
    {
        "checks": {"positive_data_acceptance": {"expected-statuses": ["2xx"]}},
        "operations": [
            {
                "include-path-regex": (
                    "^/v1/(flatten|validate|fit|locate|measure|plan|register|compare|transfer|points"
                    "|points/inverse)$"
                ),
                "checks": {
                    "positive_data_acceptance": {"expected-statuses": ["2xx", "404", "422"]}
                },
            },
            {
                "include-path-regex": "^/v1/(sites|strands)$",
                "checks": {
                    "positive_data_acceptance": {"expected-statuses": ["2xx", "404", "413", "422"]}
                },
            },
            {
                "include-path-regex": "^/v1/meshes$",
                "checks": {"positive_data_acceptance": {"expected-statuses": ["2xx", "422"]}},
            },
        ],
    }
)
schema = schemathesis.openapi.from_asgi("/openapi.json", app, config=CONFIG)

PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "dev")
EXAMPLES = int(os.environ.get("MESHFLAT_FUZZ_EXAMPLES", 200 if PROFILE == "ci" else 30))
#: What CI must reach over all operations (operations without parameters have one request).
MINIMUM_IN_CI = 2000

sent: dict[str, int] = {}

#: Real meshes for the multipart routes: the schema can only say "binary", and random bytes
#: would stop every request at the reader, before the parameters are ever used.
MESHES = {
    "ply": SAMPLES["fsaverage-head.ply"].path.read_bytes(),
    "glb": SAMPLES["lee-perry-smith.glb"].path.read_bytes(),
}


def with_real_mesh(case) -> None:
    """Put a real mesh into a generated multipart body whose parameters are an object, in the
    format they name (or PLY, named); other bodies are sent as generated."""
    body = case.body
    parts = [name for name in ("mesh", "baseline") if isinstance(body, dict) and name in body]
    if not (parts and isinstance(body.get("params"), dict)):
        return
    chosen = body["params"].get("format", "ply")
    if isinstance(chosen, str) and chosen in MESHES:
        body["params"] = {**body["params"], "format": chosen}
        body[parts[0]] = MESHES[chosen]


#: The document the requests are checked against.
DOCUMENT = app.openapi()


def valid_after_all(case) -> bool:
    """Whether a case schemathesis generated to be invalid reaches the service valid: its
    body holds the documented parts and validates against the document (schemathesis
    mutates one branch of an ``anyOf``, a rotation's ``{pole, up}`` to null, say, which
    another branch allows), and its only other invalid part is the key headers, of which
    this test sends a valid ``Authorization`` (either key admits a request)."""
    meta = case.meta
    if meta is None or not meta.generation.mode.is_negative:
        return False
    mutated = {where for where, part in meta.components.items() if part.mode.is_negative}
    if not mutated <= {ParameterLocation.BODY, ParameterLocation.HEADER}:
        return False
    if ParameterLocation.BODY not in mutated:
        return True
    body = case.body
    content = case.operation.definition.raw["requestBody"]["content"]
    if case.media_type == "multipart/form-data" and isinstance(body, dict):
        form = content["multipart/form-data"]["schema"]
        if set(body) - set(form["properties"]) or set(form["required"]) - set(body):
            return False
        body, schema = body.get("params", {}), form["properties"]["params"]
    elif case.media_type == "application/json":
        schema = content["application/json"]["schema"]
    else:
        return False
    validator = Draft202012Validator({**schema, "components": DOCUMENT["components"]})
    return validator.is_valid(body)


@schema.parametrize()
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
def test_every_generated_request_gets_a_documented_answer(case):
    with_real_mesh(case)
    # A "negative" case the document allows may be accepted: every other check still runs.
    excluded = [negative_data_rejection] if valid_after_all(case) else None
    case.call_and_validate(headers={"Authorization": f"Bearer {KEY}"}, excluded_checks=excluded)
    label = f"{case.method} {case.path}"
    sent[label] = sent.get(label, 0) + 1


def test_ci_sends_enough_generated_requests():
    """Runs after the fuzzing above (same module, in order); counts what it sent."""
    paths = app.openapi()["paths"]
    operations = {f"{method.upper()} {path}" for path in paths for method in paths[path]}
    # `sent` also has the other methods schemathesis tries on each path (405 expected).
    if not operations <= set(sent):
        missing = sorted(operations - set(sent))
        if PROFILE == "ci":  # CI runs them all: a missing one is a fault
            pytest.fail(f"not fuzzed: {missing}")
        pytest.skip(f"not every operation was fuzzed in this run (a -k selection?): {missing}")
    total = sum(sent.values())
    documented = sum(sent[label] for label in operations)
    print(f"\nschemathesis: {total:,} requests ({documented:,} to documented operations)")
    if PROFILE == "ci":
        assert total >= MINIMUM_IN_CI, sent
