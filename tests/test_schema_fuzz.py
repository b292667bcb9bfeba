"""Property-based requests generated from the committed OpenAPI document (schemathesis), sent
in-process to the app: every answer must be documented, conform to its schema, and never be a
server error, whatever the request holds."""

from __future__ import annotations

import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import positive_data_acceptance

from service.app import create_app
from service.settings import Settings

#: The service as deployed: with keys, so that the document's security is checked too (a
#: request without the key must get a 401).
KEY = "fuzz-key"
app = create_app(Settings(api_keys=(KEY,)))
schema = schemathesis.openapi.from_asgi("/openapi.json", app)


@schema.parametrize()
@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
def test_every_generated_request_gets_a_documented_answer(case):
    # A request the schema allows may still be refused with a 422: the schema cannot say
    # "sigma or pole_angle_deg, not both", nor "no point at the centre".
    case.call_and_validate(
        headers={"Authorization": f"Bearer {KEY}"}, excluded_checks=[positive_data_acceptance]
    )
