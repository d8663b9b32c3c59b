"""Where a stream's state lives between its frames: in this process (the default), or in Redis, so that any
replica behind a load balancer can take a stream's next frame (``ORPOSE_REDIS_URL``).

A stream's state is what its next frame needs: the tracker (``pipeline.track.Tracker``: its tracks, Kalman
states, bone estimates and next id), the frame count, the clock and the last frame's time, the floor it found, and
the last answer (a client that lost an answer, because the replica that computed it died, sends the frame again and
gets that answer back instead of a 409). In Redis it is one pickled value per stream under
``{prefix}{stream_id}``, written after each taken frame with a TTL of ``ORPOSE_STREAM_IDLE_S`` (the idle expiry,
kept by Redis), beside a sorted set ``{prefix}:seen`` of the streams' last use (the bound on how many streams are
held, across replicas).

Order across replicas: a frame holds the stream's Redis lock (``SET NX PX`` with a token, released only by its
holder; ``redis.asyncio.lock.Lock``) from before it reads the state to after it writes it, so two replicas never
take frames of one stream at once, and the state carries the stream's frame count as its version: a write whose
version is not the stored one plus one is refused (a lock that expired under a frame stuck longer than
``lock_timeout_s`` cannot overwrite a newer state).

Redis holds the services' own pickles: run it on a private network, as every deployment of a cache does
(docs/deploy.md).
"""

from __future__ import annotations

import pickle
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

PREFIX = "orpose:stream:"
# Written only if the stored state's version is the one the frame read (KEYS[1] state, ARGV[1] the version read
# or -1 for none, ARGV[2] the new blob, ARGV[3] ttl ms, ARGV[4] the new version).
_SAVE = """
local old = redis.call('HGET', KEYS[1], 'version')
if (old == false and ARGV[1] ~= '-1') or (old ~= false and old ~= ARGV[1]) then return 0 end
redis.call('HSET', KEYS[1], 'version', ARGV[4], 'state', ARGV[2])
redis.call('PEXPIRE', KEYS[1], ARGV[3])
return 1
"""


class StaleState(RuntimeError):
    """The stream's state changed under a frame (its lock expired and another replica took a frame)."""


class RedisStreams:
    """Stream states in Redis at ``url`` (``redis://host:6379/0``, ``unix:///path/redis.sock``)."""

    def __init__(self, url: str, idle_s: float, lock_timeout_s: float = 60.0, prefix: str = PREFIX) -> None:
        import redis.asyncio  # the `redis` extra; imported only when a URL is set

        self.url, self.idle_s, self.lock_timeout_s, self.prefix = url, idle_s, lock_timeout_s, prefix
        self.client = redis.asyncio.Redis.from_url(url, socket_timeout=5, socket_connect_timeout=5)
        self._save = self.client.register_script(_SAVE)

    def _key(self, stream_id: str) -> str:
        return self.prefix + stream_id

    async def ping(self) -> None:
        await self.client.ping()

    @asynccontextmanager
    async def hold(self, stream_id: str, wait_s: float) -> AsyncIterator[None]:
        """The stream's lock across replicas; TimeoutError when another frame holds it for more than ``wait_s``."""
        lock = self.client.lock(
            self._key(stream_id) + ":lock", timeout=self.lock_timeout_s, blocking_timeout=wait_s, sleep=0.002
        )
        if not await lock.acquire():
            raise TimeoutError(f"stream {stream_id!r} is held by another frame")
        try:
            yield
        finally:
            try:
                await lock.release()
            except Exception:  # expired under a long frame: the version check guards the state
                pass

    async def load(self, stream_id: str) -> tuple[int, dict[str, Any]] | None:
        """(version, state) of ``stream_id``, or None when it has none (never started, ended or expired)."""
        got = await self.client.hmget(self._key(stream_id), "version", "state")
        if got[0] is None:
            return None
        return int(got[0]), pickle.loads(got[1])

    async def save(self, stream_id: str, read_version: int | None, state: dict[str, Any]) -> int:
        """Write ``state`` as the version after ``read_version`` (None: a new stream); StaleState when the stored
        version moved since it was read. Returns the new version."""
        version = 0 if read_version is None else read_version + 1
        blob = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
        ttl_ms = max(int(self.idle_s * 1000), 1)
        args = [-1 if read_version is None else read_version, blob, ttl_ms, version]
        if not await self._save(keys=[self._key(stream_id)], args=args):
            raise StaleState(f"stream {stream_id!r} changed while this frame was computed")
        await self.client.zadd(self.prefix + ":seen", {stream_id: time.time()})
        return version

    async def delete(self, stream_id: str) -> dict[str, Any] | None:
        """Remove ``stream_id``; its last state, or None when it had none."""
        key = self._key(stream_id)
        async with self.client.pipeline(transaction=True) as pipe:
            pipe.hget(key, "state").delete(key).zrem(self.prefix + ":seen", stream_id)
            blob, *_ = await pipe.execute()
        return None if blob is None else pickle.loads(blob)

    async def active(self) -> int:
        """How many streams took a frame within the idle time (every replica's)."""
        seen = self.prefix + ":seen"
        await self.client.zremrangebyscore(seen, "-inf", time.time() - self.idle_s)
        return await self.client.zcard(seen)

    async def idle_waits(self) -> list[float]:
        """Seconds until each held stream expires (the Retry-After of a full server)."""
        now = time.time()
        scores = await self.client.zrange(self.prefix + ":seen", 0, -1, withscores=True)
        return [max(self.idle_s - (now - t), 0.0) for _, t in scores]

    async def aclose(self) -> None:
        await self.client.aclose()
