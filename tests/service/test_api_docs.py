"""`/docs` and `/redoc` load with no internet: their pages reference only this service's own URLs,
and the scripts and styles they reference are served."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings

_REFERENCES = re.compile(r"""(?:src|href)=["']([^"']+)["']|url:\s*['"]([^'"]+)['"]""")


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> TestClient:
    # The docs need no database: the app is not started (no lifespan).
    return TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("docs"))))


@pytest.mark.parametrize(
    ("page", "assets"),
    [
        ("/docs", {"swagger-ui-bundle.js", "swagger-ui.css", "favicon.png"}),
        ("/redoc", {"redoc.standalone.js", "favicon.png"}),
    ],
)
def test_the_api_docs_reference_only_local_urls_that_are_served(
    client: TestClient, page: str, assets: set[str]
) -> None:
    response = client.get(page)
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/html")
    html = response.text
    assert "http://" not in html and "https://" not in html and "//cdn" not in html
    urls = {a or b for a, b in _REFERENCES.findall(html)}
    assert {Path(url).name for url in urls if url.startswith("/docs-assets/")} == assets
    for url in urls:
        assert url.startswith("/"), f"{page} loads {url} from outside the service"
        fetched = client.get(url)
        assert fetched.status_code == 200, url
        assert len(fetched.content) > 1000, url


def test_swagger_ui_does_not_ask_the_online_validator(client: TestClient) -> None:
    assert '"validatorUrl": null' in client.get("/docs").text


def test_the_swagger_oauth2_redirect_page_is_served(client: TestClient) -> None:
    response = client.get("/docs/oauth2-redirect")
    assert response.status_code == 200 and "oauth2" in response.text.lower()
