"""Hostile values in every query, path and header parameter of the API, on SQLite and PostgreSQL:
JSON nested thousands deep or holding NaN and Infinity, instants at the ends of the datetime range
with offsets, NUL and other control characters (and lone surrogates), absurd integers, and
well-formed cursors that carry them. One parameter is hostile at a time, the others valid, so
each value reaches as far as it can. No request may get a 5xx; every error is a problem document.

The parameters are read from the app's own OpenAPI document (a new one is fuzzed without a change
here), plus the API key headers of its security schemes. Schemathesis (`test_fuzz_api.py`) draws
values that match the document; these are the classes an outside probe found 500s with."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import select

from service import webhooks
from service.models import EventType, Result
from service.pagination import encode_cursor
from tests.reliability.test_fuzz_api import seed
from tests.service.conftest import Api, recording

EXAMPLES = 12
URL_VALUE_CHARS = 4000
"""A longer path or query value would pass httpx's URL limit (64 KiB) once percent-encoded."""
FUZZ_SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)

# -- hostile values -------------------------------------------------------------------------------

_NON_FINITE = ("NaN", "Infinity", "-Infinity", "1e400", "-1e999")
_EDGE_INSTANTS = (
    "0001-01-01T00:00:00+23:59",
    "9999-12-31T23:59:59-23:59",
    "9999-12-31T23:59:59.999999+00:00",
    "0001-01-01T00:00:00-00:01",
    "0000-01-01T00:00:00Z",
    "10000-01-01T00:00:00Z",
)


def deep_json() -> st.SearchStrategy[str]:
    def nest(depth: int, opener: str, closer: str, core: str) -> str:
        return opener * depth + core + closer * depth

    return st.builds(
        nest,
        st.integers(1, 6000),
        st.sampled_from(["[", '{"a":', '{"frames":']),
        st.sampled_from(["]", "}", "}"]),
        st.sampled_from(["1", "NaN", '""', "[]"]),
    )


def non_finite_json() -> st.SearchStrategy[str]:
    section = st.sampled_from(["frames", "reader", "optimisation", "denoise", "x"])
    field = st.sampled_from(["base_height_above_floor_m", "max_iterations", "k", "y"])
    return st.one_of(
        st.sampled_from(_NON_FINITE),
        st.builds(
            lambda s, f, v: f'{{"{s}": {{"{f}": {v}}}}}',
            section,
            field,
            st.sampled_from(_NON_FINITE),
        ),
        st.builds(lambda v: f"[{v}]", st.sampled_from(_NON_FINITE)),
    )


def json_documents() -> st.SearchStrategy[str]:
    """JSON (as Python writes it: NaN and Infinity included) with hostile leaves."""
    leaves = st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(-(10**40), 10**40),
        control_text(),
        st.booleans(),
        st.none(),
    )
    documents = st.recursive(
        leaves,
        lambda inner: (
            st.lists(inner, max_size=3) | st.dictionaries(control_text(), inner, max_size=3)
        ),
        max_leaves=8,
    )
    return st.builds(json.dumps, documents)


def extreme_instants() -> st.SearchStrategy[str]:
    offsets = st.integers(-(23 * 60 + 59), 23 * 60 + 59).map(
        lambda minutes: (
            f"{'+' if minutes >= 0 else '-'}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}"
        )
    )
    at_the_ends = st.builds(
        lambda date, offset: date + offset,
        st.sampled_from(["0001-01-01T00:00:00", "9999-12-31T23:59:59.999999", "0001-01-01"]),
        offsets,
    )
    return st.one_of(st.sampled_from(_EDGE_INSTANTS), at_the_ends)


def control_text() -> st.SearchStrategy[str]:
    """Text with control characters (NUL first among them) and lone surrogates."""
    hostile = st.characters(categories=["Cc", "Cs"])
    return st.one_of(
        st.lists(st.one_of(hostile, st.characters()), min_size=1, max_size=12).map("".join),
        st.builds(
            lambda before, after: f"{before}\x00{after}", st.text(max_size=5), st.text(max_size=5)
        ),
    )


def absurd_integers() -> st.SearchStrategy[str]:
    return st.one_of(
        st.integers(-(10**40), 10**40).map(str),
        st.sampled_from(
            [str(2**63), str(2**63 - 1), str(2**64), "1" * 31, "-0", "²", "١٢", "1e309"]
        ),
    )


def hostile_cursors() -> st.SearchStrategy[str]:
    key = st.one_of(control_text(), extreme_instants(), absurd_integers())
    return st.one_of(
        st.builds(lambda k: encode_cursor("robots", k), key),
        st.builds(lambda a, b: encode_cursor("history", a, b), key, key),
        st.builds(lambda a, b: encode_cursor("runs", a, b), key, key),
        st.builds(lambda a: encode_cursor("history", "2026-01-01T00:00:00+00:00", a), key),
    )


HOSTILE = st.one_of(
    deep_json(),
    non_finite_json(),
    json_documents(),
    extreme_instants(),
    control_text(),
    absurd_integers(),
    hostile_cursors(),
)

# -- the parameters -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Parameter:
    method: str
    path: str
    location: str  # path | query | header
    name: str

    @property
    def label(self) -> str:
        return f"{self.method} {self.path} {self.location}:{self.name}"


def parameters(document: dict[str, Any]) -> Iterator[Parameter]:
    auth_headers = [
        scheme["name"] if scheme["type"] == "apiKey" else "Authorization"
        for scheme in document["components"]["securitySchemes"].values()
    ]
    for path, operations in document["paths"].items():
        for method, operation in operations.items():
            for parameter in operation.get("parameters", []):
                yield Parameter(method.upper(), path, parameter["in"], parameter["name"])
            if operation.get("security"):
                for header in auth_headers:
                    yield Parameter(method.upper(), path, "header", header)


def valid_path_values(api: Api) -> dict[tuple[str, str], str]:
    """A valid value of each path parameter: (path template, name) -> value."""
    with api.services.db.session() as session:
        run_id = session.scalars(select(Result.run_id)).first()
    assert run_id is not None, "seed() stores a result"
    with api.services.db.transaction() as session:
        hook = webhooks.create_webhook(
            session,
            url="http://127.0.0.1:9/hook",
            events=list(EventType),
            robot_model=None,
            secret=None,
        )
    return {
        ("*", "webhook_id"): str(hook.id),
        ("*", "robot_id"): "R1",
        ("*", "run_id"): str(run_id),
        ("/v1/tolerance-profiles/{name}", "name"): "p1",
        ("/v1/runs/{run_id}/report/{name}.png", "name"): "map-top",
        ("*", "fmt"): "urdf",
    }


def call(client: TestClient, api: Api, target: Parameter, value: str, valid: dict[Any, Any]) -> Any:
    if target.location != "header":
        value = value[:URL_VALUE_CHARS]
    path = target.path
    for name in [part.split("}")[0] for part in path.split("{")[1:]]:
        given_value = value if target.location == "path" and name == target.name else None
        if given_value is None:
            given_value = valid.get((target.path, name)) or valid[("*", name)]
        path = path.replace(
            f"{{{name}}}", quote(given_value.encode("utf-8", "surrogatepass"), safe="")
        )
    query = (
        {"kind": "end_of_line"} if target.path.endswith("/runs") and target.method == "POST" else {}
    )
    url = path + "?" + "&".join(f"{k}={v}" for k, v in query.items())
    if target.location == "query":
        encoded = quote(value.encode("utf-8", "surrogatepass"), safe="")
        url = f"{url}&{quote(target.name)}={encoded}"
    headers: dict[str, Any] = dict(api.headers("admin"))
    if target.location == "header":
        # Bytes: a header is octets; over HTTP the server would refuse most of these, the app
        # must not fail on any.
        headers[target.name] = value.encode("utf-8", "surrogatepass")
    content: bytes | None = None
    if target.method == "POST":
        content = recording()
    elif target.method == "PUT":
        content, headers["Content-Type"] = b"{}", "application/json"
    return client.request(target.method, url, content=content, headers=headers)


@pytest.fixture
def client(api: Api) -> TestClient:
    # A 500 is an answer to count here, not an exception to raise.
    return TestClient(api.client.app, raise_server_exceptions=False)


def test_hostile_values_in_any_parameter_get_4xx_problems_never_5xx(
    api: Api, client: TestClient
) -> None:
    seed(api)
    valid = valid_path_values(api)
    document = api.client.app.openapi()  # type: ignore[attr-defined]
    targets = list(parameters(document))
    assert len(targets) >= 40, [t.label for t in targets]
    failures: list[str] = []

    def fuzz(target: Parameter) -> None:
        @FUZZ_SETTINGS
        @given(value=HOSTILE)
        def check(value: str) -> None:
            response = call(client, api, target, value, valid)
            answer = (
                f"{target.label} = {value[:80]!r}: {response.status_code} {response.text[:200]}"
            )
            if response.status_code >= 500:
                failures.append(answer)
            elif response.status_code >= 400:
                content_type = response.headers["content-type"]
                assert content_type.startswith("application/problem+json"), answer

        check()

    for target in targets:
        fuzz(target)
    assert not failures, "\n".join(failures[:20])


def test_the_hostile_classes_are_drawn() -> None:
    """The strategies make what the test is about (a strategy that drifted would pass quietly)."""
    drawn: list[str] = []

    @settings(FUZZ_SETTINGS, max_examples=300)
    @given(value=HOSTILE)
    def collect(value: str) -> None:
        drawn.append(value)

    collect()
    assert any(v.count("[") > 1000 or v.count("{") > 1000 for v in drawn), "deep JSON"
    assert any(token in v for v in drawn for token in ("NaN", "Infinity")), "non-finite JSON"
    assert any("\x00" in v for v in drawn), "NUL"
    assert any(v.startswith(("0001-01-01", "9999-12-31")) and v[-6] in "+-" for v in drawn)
    assert any(v.lstrip("-").isdigit() and len(v.lstrip("-")) > 19 for v in drawn), "absurd ints"
