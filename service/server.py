"""How the API is served: uvicorn's httptools protocol with a bound on the size of a request's
head (request line and headers).

httptools keeps a header in memory until its line ends, so one client sending an endless header
grows the server's memory without limit (measured: +1 MiB per MiB sent). The plain h11 parser has
such a bound but drained uploads at ~130 MB/s, under target (pyproject.toml); this keeps httptools
and refuses a head past `MAX_HEAD_BYTES` with a 431 problem document, then closes the connection.
"""

from __future__ import annotations

import json
from typing import Any

from service.problem_details import PROBLEM_MEDIA_TYPE, problem_document

MAX_HEAD_BYTES = 1024 * 1024
"""A request's line and headers together; counted per received chunk, so one chunk (asyncio reads
up to 256 KiB) may pass the bound before the head is refused."""


def http_protocol() -> Any:
    """The `http` protocol for `uvicorn.Config`: httptools with the bound, or h11 with its own
    bound where httptools is missing."""
    try:
        from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol
    except ImportError:  # uvicorn without its [standard] extra
        return "h11"

    class BoundedHeadProtocol(HttpToolsProtocol):
        _head_bytes: int | None = 0
        """Bytes of the current request's head received so far; None once its headers ended."""

        def data_received(self, data: bytes) -> None:
            super().data_received(data)
            if self._head_bytes is None or self.transport.is_closing():
                return
            self._head_bytes += len(data)
            if self._head_bytes > MAX_HEAD_BYTES:
                self.logger.warning("request head over %d bytes refused", MAX_HEAD_BYTES)
                self.transport.write(_HEAD_TOO_LARGE)
                self.transport.close()

        def on_headers_complete(self) -> None:
            self._head_bytes = None
            super().on_headers_complete()

        def on_message_complete(self) -> None:
            super().on_message_complete()
            self._head_bytes = 0

    return BoundedHeadProtocol


_BODY = json.dumps(
    problem_document(
        "request-head-too-large",
        "Request header fields too large",
        431,
        f"the request line and headers exceed {MAX_HEAD_BYTES} bytes; shorten them",
    )
).encode()
_HEAD_TOO_LARGE = (
    b"HTTP/1.1 431 Request Header Fields Too Large\r\n"
    + f"content-type: {PROBLEM_MEDIA_TYPE}\r\ncontent-length: {len(_BODY)}\r\n".encode()
    + b"connection: close\r\n\r\n"
    + _BODY
)
