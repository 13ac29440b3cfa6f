"""The contract holds: schemathesis fuzzes every operation of the app against its own OpenAPI
document (a bounded, derandomized run) with a real storage folder and a real Redis for the queue
(no worker: jobs stay queued), keys configured and sent.

Checks: all of schemathesis' defaults (not_a_server_error, status_code_conformance,
content_type_conformance, response_schema_conformance, response_headers_conformance,
positive_data_acceptance, negative_data_rejection, missing_required_header, ignored_auth,
unsupported_method, allow_header_conformance, ...) and :func:`schema_valid_requests_pass_the_door`.
"""

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.config import SchemathesisConfig

from hairport.service.app import create_app
from hairport.settings import Settings

KEY = "fuzz-key"
AUTH = {"Authorization": f"Bearer {KEY}"}
#: examples per operation and phase: the whole run takes about a minute on 2 cores
MAX_EXAMPLES = 25
#: a schema-valid upload can still hold a bad file (the schema cannot say what a valid mesh is): such a
#: refusal (413 too large, 415 no format, 422 unreadable) is accepted; schemathesis' own statuses otherwise
CONTENT_REFUSALS = ("413", "415", "422")
POSITIVE_STATUSES = ["2xx", "3xx", "401", "403", "404", "409", "429", *CONTENT_REFUSALS]
#: codes that mean "a rule the schema states was broken": a schema-valid request must never get one
DOOR_CODES = frozenset({"invalid_request", "bad_units", "bad_axis", "bad_idempotency_key", "bad_request"})
#: rules tying two fields together, which a schema does not state: (code, words of its detail)
CROSS_FIELD_RULES = (("bad_axis", "perpendicular"),)
CONFIG = {
    "checks": {"positive_data_acceptance": {"expected-statuses": POSITIVE_STATUSES}},
    # a readiness probe answers 503 while no worker listens: that is its documented answer, not a server error
    "operations": [{"include-path": "/readyz",
                    "checks": {"not_a_server_error": {"expected-statuses": ["2xx", "3xx", "4xx", "503"]},
                               "positive_data_acceptance": {"expected-statuses": ["200", "503"]}}}],
}


@schemathesis.check
def schema_valid_requests_pass_the_door(ctx, response, case):
    """A request the schema calls valid is refused only for what the schema cannot state (its files'
    content, the deployment's limits, what exists): never with a code of a rule the schema states."""
    if case.meta is None or not case.meta.generation.mode.is_positive or response.status_code < 400:
        return None
    media_type = (response.headers.get("content-type") or [""])[0]
    problem = response.json() if media_type.startswith("application/problem+json") else {}
    cross_field = any(problem.get("code") == code and words in problem.get("detail", "")
                      for code, words in CROSS_FIELD_RULES)
    if problem.get("code") in DOOR_CODES and not cross_field:
        raise AssertionError(f"schema-valid request refused with {response.status_code} {problem['code']}: "
                             f"{problem.get('detail')}")
    return None


@pytest.fixture(scope="module")
def api_schema(redis_url, tmp_path_factory):
    app = create_app(Settings(storage_dir=tmp_path_factory.mktemp("storage"), api_keys=KEY, redis_url=redis_url))
    return schemathesis.openapi.from_asgi("/openapi.json", app, config=SchemathesisConfig.from_dict(CONFIG))


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, derandomize=True, database=None, deadline=None,
          suppress_health_check=list(HealthCheck))
def test_every_operation_keeps_its_contract(case):
    case.call_and_validate(headers=AUTH)
