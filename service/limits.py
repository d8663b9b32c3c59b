"""Overload protection: a cap on the body (size and time to receive it), a bound on the requests still
receiving their body, and a bound on requests in flight.

The body cap is a pure ASGI middleware, so it acts before anything reads the body: a declared Content-Length
over the limit is answered 413 at once, and a body that streams past the limit (chunked, or a lying header)
fails with 413 as soon as it does. A body that takes longer than ``timeout_s`` to arrive gets a 408.

Receiving and computing are admitted separately, so that slow uploads cannot lock anyone out of the models:
a request holds one of ``max_receiving`` *receiving* places from the first read of its body until its last
byte has arrived (beyond it: 503), and only then asks for one of the ``max_in_flight`` *inference* slots
(``InFlightLimiter``, taken by the route; beyond it: 503). Both answer at once with Retry-After instead of
queueing without end.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable

import anyio
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send


class BodyLimitMiddleware:
    """Reject request bodies larger than ``max_bytes`` (413) or slower than ``timeout_s`` to arrive (408), and
    more than ``max_receiving`` bodies arriving at once (503 with ``Retry-After: retry_after_s``).

    The receiving place is taken on the app's first read of the body, that is after the route's dependencies
    (the token) have passed, and given back when the body is complete or the request ends.

    ``receiving``: the limiter of receiving places, when the app reads it too (the metrics); ``rejected``: called
    with the reason of each refusal (``service.metrics.REJECTIONS``).
    """

    def __init__(
        self,
        app: ASGIApp,
        max_bytes: int,
        timeout_s: float,
        max_receiving: int = 32,
        retry_after_s: int = 1,
        receiving: InFlightLimiter | None = None,
        rejected: Callable[[str], None] | None = None,
    ) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.timeout_s = timeout_s
        self.receiving = receiving if receiving is not None else InFlightLimiter(max_receiving)
        self.retry_after_s = retry_after_s
        self.rejected = rejected or (lambda reason: None)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope["headers"]).get(b"content-length")
        if declared is not None:
            try:
                declared_bytes = int(declared)
            except ValueError:
                await _send_error(send, 400, "Content-Length is not an integer")
                return
            if declared_bytes > self.max_bytes:
                self.rejected("body_too_large")
                await _send_error(send, 413, self._too_large(declared_bytes))
                return
        received = 0
        done = False
        holding = False
        deadline = time.monotonic() + self.timeout_s

        def release() -> None:
            nonlocal holding
            if holding:
                holding = False
                self.receiving.release()

        async def limited_receive() -> Message:
            nonlocal received, done, holding
            if done:  # after the body, receive only waits for a disconnect: no deadline applies
                return await receive()
            if not holding:
                if not self.receiving.try_acquire():
                    self.rejected("receiving_full")
                    raise HTTPException(
                        503,
                        f"the server is receiving {self.receiving.capacity} uploads already "
                        f"(ORPOSE_MAX_RECEIVING); retry after {self.retry_after_s} s",
                        headers={"Retry-After": str(self.retry_after_s)},
                    )
                holding = True
            try:
                with anyio.fail_after(max(deadline - time.monotonic(), 0.0)):
                    message = await receive()
            except TimeoutError:
                detail = f"the request body did not arrive within {self.timeout_s:g} s"
                self.rejected("body_timeout")
                raise HTTPException(408, detail) from None
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    self.rejected("body_too_large")
                    raise HTTPException(413, self._too_large(received))
                done = not message.get("more_body", False)
            elif message["type"] == "http.disconnect":
                done = True
            if done:
                release()
            return message

        try:
            await self.app(scope, limited_receive, send)
        finally:
            release()

    def _too_large(self, size: int) -> str:
        limit = self.max_bytes
        return f"request body of {size}+ bytes exceeds the limit of {limit} bytes (ORPOSE_MAX_BODY_BYTES)"


async def _send_error(send: Send, status: int, detail: str) -> None:
    body = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    # The body was not read: ask the client to close, so that unread bytes are not taken for the next request.
    headers.append((b"connection", b"close"))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class InFlightLimiter:
    """At most ``capacity`` holders at once. Used only from the event loop, so a plain counter is safe."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.in_flight = 0

    def try_acquire(self) -> bool:
        if self.in_flight >= self.capacity:
            return False
        self.in_flight += 1
        return True

    def release(self) -> None:
        self.in_flight -= 1
