"""Stopping the models' work for a client that has gone.

A thread cannot be killed, and a torch forward pass cannot be interrupted from outside. But every layer of
both models is an ``nn.Module``, so one global forward pre-hook can check, before each layer, whether the
request that the current thread works for has been cancelled, and raise :class:`Cancelled` there. The work
then stops at the next layer (a few ms to a few hundred ms), not at the end of the frame.

The hook reads a thread-local event, set only around a cancellable call: code outside
:func:`run_cancellable` (training, offline evaluation, other threads) is never affected.

``await run_until_disconnected(receive, fn, limiter)`` runs ``fn`` on a worker thread while it watches the
ASGI ``receive`` channel; a ``http.disconnect`` sets the event (and stops any wait for a free worker), and
the call raises :class:`ClientGone`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TypeVar

import anyio
import torch
from starlette.types import Receive

T = TypeVar("T")
_log = logging.getLogger("uvicorn.error")  # uvicorn's own log: shown at INFO with the default log config
_local = threading.local()
_hook_lock = threading.Lock()
_hook = None


class Cancelled(Exception):
    """Raised inside a model's forward pass when its request has been cancelled."""


class ClientGone(Exception):
    """The client disconnected before its result was ready; ``stopped_ms``: from the disconnect to the end of
    the work."""

    def __init__(self, stopped_ms: float) -> None:
        super().__init__(f"the client disconnected; its work stopped {stopped_ms:.0f} ms later")
        self.stopped_ms = stopped_ms


def _check(module: torch.nn.Module, args) -> None:
    event = getattr(_local, "event", None)
    if event is not None and event.is_set():
        raise Cancelled("the request was cancelled")


def install_hook() -> None:
    """Register the global forward pre-hook once per process (idempotent)."""
    global _hook
    with _hook_lock:
        if _hook is None:
            _hook = torch.nn.modules.module.register_module_forward_pre_hook(_check)


def run_cancellable(fn: Callable[[], T], event: threading.Event) -> T:
    """``fn()`` in this thread, stopping at its next module call once ``event`` is set."""
    install_hook()
    _local.event = event
    try:
        if event.is_set():
            raise Cancelled("the request was cancelled before it started")
        return fn()
    finally:
        _local.event = None


async def run_until_disconnected(
    receive: Receive, fn: Callable[[], T], limiter: anyio.CapacityLimiter | None = None
) -> T:
    """``fn()`` on a worker thread (bounded by ``limiter``); raises :class:`ClientGone` if the client leaves.

    ``receive`` must be past the request body, so that its next message is ``http.disconnect``.
    """
    event = threading.Event()
    gone_at: list[float] = []
    outcome: dict = {}
    work = anyio.CancelScope()

    async def watch() -> None:
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                gone_at.append(time.perf_counter())
                event.set()  # the worker thread stops at its next layer
                work.cancel()  # and a wait for a free worker ends at once
                return

    async with anyio.create_task_group() as tg:
        tg.start_soon(watch)
        with work:
            try:
                outcome["value"] = await anyio.to_thread.run_sync(
                    lambda: run_cancellable(fn, event), limiter=limiter
                )
            except Cancelled:
                pass
            except Exception as exc:  # re-raised below, outside the task group (no ExceptionGroup)
                outcome["error"] = exc
        tg.cancel_scope.cancel()  # stop watching
    if gone_at:
        stopped_ms = (time.perf_counter() - gone_at[0]) * 1e3
        _log.info("client disconnected during inference; its work stopped %.0f ms later", stopped_ms)
        raise ClientGone(stopped_ms)
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]
