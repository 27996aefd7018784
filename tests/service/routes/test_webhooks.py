"""The webhooks API, on both databases: an admin registers, lists and deletes webhooks and reads
each one's deliveries with their outcome; every bad input is a problem document."""

from __future__ import annotations

import uuid
from datetime import timedelta

import httpx

from tests.service.conftest import Api, problem_type
from tests.service.documents import result_document
from tests.service.routes.accepted import finished
from tests.service.webhook_receiver import Receiver
from workers.webhooks import DeliveryOptions, deliver_due

HOOK = {"url": "http://127.0.0.1:9/hook", "events": ["run.finished", "verdict.failed"]}


def test_register_list_show_delete(api: Api) -> None:
    created = api.client.post("/v1/webhooks", json=HOOK, headers=api.headers("admin"))
    assert created.status_code == 201, created.text
    body = created.json()
    assert body["secret"].startswith("whsec_") and body["events"] == [
        "run.finished",
        "verdict.failed",
    ]
    listed = api.client.get("/v1/webhooks", headers=api.headers("admin")).json()["items"]
    assert [h["id"] for h in listed] == [body["id"]] and "secret" not in listed[0]
    shown = api.client.get(f"/v1/webhooks/{body['id']}", headers=api.headers("admin"))
    assert shown.json()["url"] == HOOK["url"]
    deleted = api.client.delete(f"/v1/webhooks/{body['id']}", headers=api.headers("admin"))
    assert deleted.status_code == 204
    assert api.client.get("/v1/webhooks", headers=api.headers("admin")).json()["items"] == []
    gone = api.client.get(f"/v1/webhooks/{body['id']}", headers=api.headers("admin"))
    assert gone.status_code == 404 and problem_type(gone) == "webhook-not-found"


def test_a_given_secret_is_kept(api: Api) -> None:
    secret = "s" * 32
    body = api.client.post(
        "/v1/webhooks",
        json={**HOOK, "secret": secret, "robot_model": "amr-2"},
        headers=api.headers("admin"),
    ).json()
    assert body["secret"] == secret and body["robot_model"] == "amr-2"


def test_deliveries_are_listed_with_their_outcome(api: Api) -> None:
    receiver = Receiver("r" * 32, script=lambda number, event: 500 if number == 1 else 200).start()
    try:
        hook = api.client.post(
            "/v1/webhooks",
            json={"url": receiver.url, "events": ["run.finished"], "secret": "r" * 32},
            headers=api.headers("admin"),
        ).json()
        run_id = finished(api, result_document())
        options = DeliveryOptions(backoff_base=timedelta(hours=1))
        with httpx.Client() as client:
            deliver_due(api.services.db, client, "test", options)
        page = api.client.get(f"/v1/webhooks/{hook['id']}/deliveries", headers=api.headers("admin"))
        (delivery,) = page.json()["items"]
        assert delivery["status"] == "pending" and delivery["attempts"] == 1
        assert delivery["last_status_code"] == 500 and delivery["run_id"] == run_id
        assert delivery["payload"]["id"] == delivery["event_id"]
        failed = api.client.get(
            f"/v1/webhooks/{hook['id']}/deliveries?status=delivered", headers=api.headers("admin")
        )
        assert failed.json()["items"] == []
    finally:
        receiver.stop()


def test_deliveries_page_by_cursor(api: Api) -> None:
    hook = api.client.post("/v1/webhooks", json=HOOK, headers=api.headers("admin")).json()
    for _ in range(3):
        finished(api, result_document(passed=False))  # two events each
    seen: list[str] = []
    url = f"/v1/webhooks/{hook['id']}/deliveries?limit=4"
    page = api.client.get(url, headers=api.headers("admin")).json()
    seen += [d["id"] for d in page["items"]]
    page = api.client.get(
        f"{url}&cursor={page['next_cursor']}", headers=api.headers("admin")
    ).json()
    seen += [d["id"] for d in page["items"]]
    assert len(seen) == len(set(seen)) == 6 and page["next_cursor"] is None


def test_webhooks_are_for_admins(api: Api) -> None:
    for key in ("read", "override", "upload"):
        response = api.client.post("/v1/webhooks", json=HOOK, headers=api.headers(key))
        assert response.status_code == 403 and problem_type(response) == "forbidden"
        listed = api.client.get("/v1/webhooks", headers=api.headers(key))
        assert listed.status_code == 403
    assert problem_type(api.client.get("/v1/webhooks")) == "unauthenticated"


def test_bad_webhooks_are_refused(api: Api) -> None:
    bodies = [
        {**HOOK, "url": "ftp://example.com/x"},
        {**HOOK, "url": "not a url"},
        {**HOOK, "url": "http://h/" + "x" * 2100},
        {**HOOK, "events": []},
        {**HOOK, "events": ["run.exploded"]},
        {**HOOK, "secret": "short"},
        {**HOOK, "robot_model": "bad model"},
        {**HOOK, "extra": True},
        {"events": ["run.finished"]},
    ]
    for body in bodies:
        response = api.client.post("/v1/webhooks", json=body, headers=api.headers("admin"))
        assert response.status_code == 422 and problem_type(response) == "invalid-request", body


def test_unknown_webhooks_and_bad_cursors(api: Api) -> None:
    missing = uuid.uuid4()
    for method, path in (
        ("GET", f"/v1/webhooks/{missing}"),
        ("DELETE", f"/v1/webhooks/{missing}"),
        ("GET", f"/v1/webhooks/{missing}/deliveries"),
    ):
        response = api.client.request(method, path, headers=api.headers("admin"))
        assert response.status_code == 404 and problem_type(response) == "webhook-not-found"
    hook = api.client.post("/v1/webhooks", json=HOOK, headers=api.headers("admin")).json()
    bad = api.client.get(
        f"/v1/webhooks/{hook['id']}/deliveries?cursor=zzz", headers=api.headers("admin")
    )
    assert bad.status_code == 400 and problem_type(bad) == "invalid-cursor"
    status = api.client.get(
        f"/v1/webhooks/{hook['id']}/deliveries?status=lost", headers=api.headers("admin")
    )
    assert status.status_code == 422
