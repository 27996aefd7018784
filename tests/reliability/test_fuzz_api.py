"""Schemathesis against the app's own OpenAPI document, with a valid admin key, on SQLite and
PostgreSQL: generated requests for every operation (stateless), then sequences that follow the
links schemathesis infers from the document (upload -> run -> report/exports, robots -> robot,
profiles -> profile). No request may get a 5xx, and every answer must match the document."""

from __future__ import annotations

import copy
import hashlib
import uuid
from typing import Any

import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis import checks
from schemathesis.core.parameters import ParameterLocation
from schemathesis.core.result import Ok
from schemathesis.specs.openapi.schemas import OpenApiSchema

from service import repository
from service.models import ApiKey, Base
from tests.service.conftest import Api, recording
from tests.service.documents import result_document

EXAMPLES = 10
# Schema-valid is not always valid here: an upload body is any bytes to the schema but must be a
# recording (415), a cursor any string but one the API made (400). Every other check stays on.
EXCLUDED = [checks.positive_data_acceptance]
UPLOAD = "POST /v1/robots/{robot_id}/runs"
ROUNDS = 10
FUZZ_SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    database=None,
    derandomize=True,
    suppress_health_check=list(HealthCheck),
)


def seed(api: Api) -> None:
    """A robot, a queued run and a finished one, for requests to find (after any earlier state
    but the keys is removed: a stateful sequence must meet the same service each time it runs)."""
    with api.services.db.transaction() as session:
        for table in reversed(Base.metadata.sorted_tables):
            if table is not ApiKey.__table__:
                session.execute(table.delete())
    for _ in range(2):
        response = api.upload("R1", recording())
        assert response.status_code == 202, response.text
    with api.services.db.transaction() as session:
        repository.store_result(session, uuid.UUID(response.json()["id"]), result_document())


def app_schema(api: Api, *, links: bool = False) -> OpenApiSchema:
    """The app's OpenAPI document for schemathesis, calling the app in this process.

    With `links`, the document gains one link schemathesis cannot infer: a listed robot's id to
    an upload for it (an upload's path names a robot; its body is binary, so it is no entry point
    of schemathesis' sequences). The links from the upload on (to the run, its report and its
    exports) are inferred."""
    app: Any = api.client.app
    document = copy.deepcopy(app.openapi())
    if links:
        listed = document["paths"]["/v1/robots"]["get"]["responses"]["200"]
        listed["links"] = {
            "UploadForListedRobot": {
                "operationRef": "#/paths/~1v1~1robots~1{robot_id}~1runs/post",
                "parameters": {"robot_id": "$response.body#/items/0/id"},
            }
        }
    schema = schemathesis.openapi.from_dict(document)
    schema.app = app
    return schema


def valid_but_for_the_body(case: Any) -> bool:
    """Whether schemathesis drew every part of `case` valid but perhaps its body (an upload's
    body is drawn negative, as random bytes: `before_call` replaces it)."""
    return not any(
        case.meta.is_negative_at(location)
        for location in case.meta.components
        if location is not ParameterLocation.BODY
    )


def make_upload_valid(case: Any) -> None:
    """A positive upload's headers that schemathesis draws as any string made valid: a drawn
    X-Content-SHA256 is the body's digest, a drawn X-Fleetcal-Config a config. Drawn at random,
    they are refused (422, 400), and so the upload was valid only when neither was drawn: with a
    few such uploads in a test, now and then none was, the linked sequences never reached a run,
    and the test's last assertion failed (36 runs: 2 to 16 uploads queued of 16 to 37 tried).
    Their refusals are the stateless test's and test_uploads'."""
    drawn = case.headers or {}
    if "X-Content-SHA256" in drawn:
        drawn["X-Content-SHA256"] = hashlib.sha256(case.body).hexdigest()
    if "X-Fleetcal-Config" in drawn:
        drawn["X-Fleetcal-Config"] = "{}"


def test_every_operation_answers_generated_requests_without_server_errors(api: Api) -> None:
    seed(api)
    schema = app_schema(api)
    headers = api.headers("admin")
    operations = [result.ok() for result in schema.get_all_operations() if isinstance(result, Ok)]
    assert len(operations) >= 16, [op.label for op in operations]
    for operation in operations:

        @FUZZ_SETTINGS
        @given(case=operation.as_strategy())
        def check(case: Any) -> None:
            case.call_and_validate(headers=headers, excluded_checks=EXCLUDED)

        check()


def test_linked_sequences_keep_the_service_consistent(api: Api) -> None:
    schema = app_schema(api, links=True)
    inference = schema.apply_stateful_inference(None)
    assert inference.selected >= 10, "upload -> run, robots -> robot, ... links are inferred"
    headers = api.headers("admin")
    answered: set[tuple[str, int]] = set()

    class Workflow(schema.as_state_machine()):  # type: ignore[misc]
        def setup(self) -> None:
            seed(api)

        def before_call(self, case: Any) -> None:
            if case.operation.label == UPLOAD:
                # Random bytes are never a recording (415): upload a real one so that the
                # sequence goes on to the run, its report and its exports.
                case.body = recording()
                if valid_but_for_the_body(case):
                    make_upload_valid(case)

        def get_call_kwargs(self, case: Any) -> dict[str, Any]:
            return {"headers": headers}

        def validate_response(self, response: Any, case: Any, **kwargs: Any) -> None:
            answered.add((case.operation.label, response.status_code))
            case.validate_response(response, excluded_checks=EXCLUDED, headers=headers)
            if case.operation.label == UPLOAD and valid_but_for_the_body(case):
                # A valid upload is queued, or refused as a reused Idempotency-Key (one drawn
                # twice in a sequence, with another kind).
                reused = "Idempotency-Key" in (case.headers or {}) and (
                    response.status_code == 422
                    and response.json()["type"].endswith(":idempotency-key-reused")
                )
                assert response.status_code == 202 or reused, response.text

    # Not derandomized: schemathesis' link choices draw from a true random source. How many
    # sequences follow the link from a listed robot to an upload is such a draw too (5 to 37
    # uploads in 30 examples, measured), so the sequences run in rounds until one has been
    # queued: the link is followed whatever the draw, at the cost of one round almost always.
    for _ in range(ROUNDS):
        Workflow.run(
            settings=settings(
                FUZZ_SETTINGS,
                max_examples=30,
                stateful_step_count=10,
                derandomize=False,
            )
        )
        if (UPLOAD, 202) in answered:
            break
    # The links were followed: a listed robot got an upload (only a link leads there). How far
    # each sequence goes on from it (run, report, exports) is schemathesis' random choice.
    assert (UPLOAD, 202) in answered, sorted(answered)
