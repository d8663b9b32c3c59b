"""Stopping the models' work for a client that has gone.

A thread cannot be killed, and a torch op cannot be interrupted from outside. Two things stop the work soon:

- every layer of both models is an ``nn.Module``, so one global forward pre-hook checks, before each layer,
  whether the request that the current thread works for has been cancelled, and raises :class:`Cancelled`;
- between layers (building the crops, lifting and aggregating), :meth:`CancelToken.cancel` raises
  :class:`Cancelled` asynchronously in the worker thread (``PyThreadState_SetAsyncExc``), which Python
  delivers at the thread's next bytecode, that is when the current torch op returns;
- a network run by an inference runtime (``posenet.runtime.graphs``: OpenVINO, ONNX Runtime) is one long call, which
  :func:`posenet.runtime.graphs.stop_call` ends (OpenVINO cancels the request, ONNX Runtime sets ``terminate``).

So the work stops within one op or layer of the disconnect, not at the end of the frame. Both act only on a
call run by :meth:`CancelToken.run`: other code and other threads (training, offline evaluation) are never
affected, and an asynchronous exception not yet delivered when the call ends is withdrawn.

``await run_until_disconnected(receive, fn, limiter)`` runs ``fn`` on a worker thread while it watches the
ASGI ``receive`` channel; a ``http.disconnect`` cancels it (and ends any wait for a free worker), and the
call raises :class:`ClientGone`.
"""

from __future__ import annotations

import ctypes
import logging
import threading
import time
from collections.abc import Callable
from typing import TypeVar

import anyio
import torch
from starlette.types import Receive

from posenet.runtime.graphs import stop_call

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


class CancelToken:
    """One request's cancellation: :meth:`cancel` (any thread) stops the work running under :meth:`run`."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self._lock = threading.Lock()
        self._thread: int | None = None  # the worker running the call, while it runs

    def cancel(self) -> None:
        with self._lock:
            if self.event.is_set():
                return
            self.event.set()
            if self._thread is not None:
                _async_raise(self._thread, Cancelled)
                stop_call(self._thread)  # an inference runtime's call (OpenVINO, ONNX Runtime) ends at once

    def run(self, fn: Callable[[], T]) -> T:
        """``fn()`` in this thread, stopped by :class:`Cancelled` once :meth:`cancel` is called."""
        install_hook()
        _local.event = self.event
        with self._lock:
            if self.event.is_set():
                raise Cancelled("the request was cancelled before it started")
            self._thread = threading.get_ident()
        try:
            return fn()
        finally:
            _local.event = None
            with self._lock:
                self._thread = None
                if self.event.is_set():  # withdraw a Cancelled that has not been delivered yet
                    _async_raise(threading.get_ident(), None)


def _async_raise(thread: int, exc: type[BaseException] | None) -> None:
    """Raise ``exc`` in ``thread`` at its next bytecode (None: withdraw a pending one)."""
    ctypes.pythonapi.PyThreadState_SetAsyncExc(
        ctypes.c_ulong(thread), None if exc is None else ctypes.py_object(exc)
    )


async def run_until_disconnected(
    receive: Receive, fn: Callable[[], T], limiter: anyio.CapacityLimiter | None = None
) -> T:
    """``fn()`` on a worker thread (bounded by ``limiter``); raises :class:`ClientGone` if the client leaves.

    ``receive`` must be past the request body, so that its next message is ``http.disconnect``.
    """
    token = CancelToken()
    gone_at: list[float] = []
    outcome: dict = {}
    work = anyio.CancelScope()

    async def watch() -> None:
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                gone_at.append(time.perf_counter())
                token.cancel()  # the worker thread stops at its next op or layer
                work.cancel()  # and a wait for a free worker ends at once
                return

    async with anyio.create_task_group() as tg:
        tg.start_soon(watch)
        with work:
            try:
                outcome["value"] = await anyio.to_thread.run_sync(lambda: token.run(fn), limiter=limiter)
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
