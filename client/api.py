"""The fleetcal API over httpx: the key in `X-API-Key`, problem documents turned into
`RefusedError`, and retries with exponential backoff (and jitter) on network errors and 502-504."""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from typing import Any

import httpx

from client.errors import RefusedError, UnreachableError

RETRY_STATUSES = frozenset({502, 503, 504})
_TIMEOUT = httpx.Timeout(30.0, connect=10.0)


class Api:
    def __init__(
        self,
        url: str,
        key: str | None,
        *,
        retries: int = 6,
        backoff_s: float = 1.0,
        max_backoff_s: float = 30.0,
        on_retry: Callable[[str], None] | None = None,
    ) -> None:
        self.url = url.rstrip("/")
        self.headers = {"X-API-Key": key} if key else {}
        self.retries = retries
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self.on_retry = on_retry or (lambda message: None)

    def request(
        self, method: str, path: str, *, ok: tuple[int, ...] = (200,), **kwargs: Any
    ) -> httpx.Response:
        """The answer to `method path`, retried as the class says; `RefusedError` for a problem,
        `UnreachableError` when every attempt failed. `content` may be a callable returning a fresh
        iterable per attempt (a streamed body cannot be replayed)."""
        content = kwargs.pop("content", None)
        headers = {**self.headers, **kwargs.pop("headers", {})}
        for attempt in range(self.retries + 1):
            body = content() if callable(content) else content
            try:
                response = httpx.request(
                    method,
                    self.url + path,
                    headers=headers,
                    content=body,
                    timeout=_TIMEOUT,
                    **kwargs,
                )
            except httpx.TransportError as err:
                reason = f"cannot reach {self.url} ({type(err).__name__}: {err or 'no detail'})"
                retry_after = None
            else:
                if response.status_code in ok:
                    return response
                if response.status_code not in RETRY_STATUSES:
                    raise RefusedError(describe_problem(response))
                reason = describe_problem(response)
                retry_after = _retry_after(response)
            if attempt == self.retries:
                raise UnreachableError(
                    f"{reason}; gave up after {self.retries + 1} attempts. Is the service "
                    "running (`fleetcal serve`) and --url right? Running the same command again "
                    "never makes a second run."
                )
            delay = min(self.max_backoff_s, self.backoff_s * 2**attempt) * random.uniform(0.5, 1)
            delay = max(delay, min(retry_after or 0.0, self.max_backoff_s))
            self.on_retry(f"{reason}; retrying in {delay:.1f} s ({attempt + 1}/{self.retries})")
            time.sleep(delay)
        raise AssertionError("unreachable")  # the loop returns or raises

    def json(self, method: str, path: str, **kwargs: Any) -> Any:
        return self.request(method, path, **kwargs).json()


def describe_problem(response: httpx.Response) -> str:
    """`HTTP 409 idempotency-key-reused: <detail>` from a problem document, else the body's head."""
    try:
        problem = response.json()
        slug = str(problem.get("type", "")).rsplit("/", 1)[-1] or problem.get("title", "")
        detail = problem.get("detail") or problem.get("title") or ""
    except (ValueError, AttributeError):
        slug, detail = response.reason_phrase, response.text[:200]
    return f"the service answered HTTP {response.status_code} {slug}: {detail}".rstrip(": ")


def _retry_after(response: httpx.Response) -> float | None:
    value = response.headers.get("Retry-After", "")
    return float(value) if value.isdigit() else None
