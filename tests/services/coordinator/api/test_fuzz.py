"""Schemathesis fuzz of the OpenAPI document: no input may produce a 5xx, on either database.

Each operation gets a few generated examples (positive and negative) through the real app;
bounded so the whole file stays well under a minute. The loop over operations is explicit
because schemathesis' lazy pytest fixture loader does not run under this pytest.
"""

from __future__ import annotations

import itertools

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.settings import Settings

pytestmark = pytest.mark.slow

EXAMPLES_PER_OPERATION = 8


@pytest.mark.timeout(120)
def test_no_input_gives_a_server_error(settings: Settings, sessions: object) -> None:
    # Imported here, not at the top: collecting the default suite (which leaves this slow test
    # out) would otherwise load schemathesis, seconds of every run.
    import schemathesis
    from hypothesis import HealthCheck, given
    from hypothesis import settings as hypothesis_settings
    from hypothesis.errors import Unsatisfiable
    from schemathesis import checks

    # No 5xx, and every response matches the document: its status codes, content types,
    # headers and body schemas. (Not "valid data is accepted": the spec cannot express every
    # rule, e.g. "a file or a name".)
    checks_to_run = [
        checks.not_a_server_error,
        checks.status_code_conformance,
        checks.content_type_conformance,
        checks.response_headers_conformance,
        checks.response_schema_conformance,
    ]
    app = create_app(settings)
    with TestClient(app) as client:
        # Something to find: low ids exist, so GET/cancel/delete reach the services.
        object_id = client.post("/objects", data={"name": "sphere"}).json()["id"]
        for _ in range(3):
            client.post(
                "/explorations",
                json={"object_id": object_id, "gripper": "robotiq_3f", "grid": {"dtheta": 1.0}},
            )
        schema = schemathesis.openapi.from_asgi("/openapi.json", app)
        operations = [result.ok() for result in schema.get_all_operations()]
        assert len(operations) >= 10
        failures: list[str] = []

        for operation, mode in itertools.product(operations, schemathesis.GenerationMode):

            @given(case=operation.as_strategy(generation_mode=mode))
            @hypothesis_settings(
                max_examples=EXAMPLES_PER_OPERATION,
                deadline=None,
                database=None,
                suppress_health_check=list(HealthCheck),
            )
            def check(case: schemathesis.Case) -> None:
                try:
                    case.call_and_validate(checks=checks_to_run)
                except Exception as exc:  # schemathesis reports failures as exception groups
                    failures.append(f"{case.method} {case.formatted_path}: {exc}"[:1500])

            try:
                check()
            except Unsatisfiable:
                # No invalid input exists for operations without parameters (e.g. /healthz).
                assert mode is schemathesis.GenerationMode.NEGATIVE
    assert not failures, "\n".join(failures)
