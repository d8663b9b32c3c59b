"""The Redis stream store against a real redis-server: round trips, versions, expiry, the lock, the bound."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from redis_harness import redis_server

from pipeline.track import Tracker
from service.stream_store import RedisStreams, StaleState


@pytest.fixture(scope="module")
def redis_url(tmp_path_factory):
    with redis_server(tmp_path_factory.mktemp("redis")) as url:
        yield url


def run(coro):
    return asyncio.run(coro)


def _tracker_after_frames(frames: int) -> Tracker:
    tracker, rng = Tracker(), np.random.default_rng(0)
    joints = rng.normal(0, 1000, (3, 1, 3)) + rng.normal(0, 200, (3, 10, 3))
    for f in range(frames):
        tracker.update(joints + 5.0 * f, np.full((3, 10), 30.0), f / 15)
    return tracker


def test_a_tracker_goes_through_redis_and_tracks_on_as_the_one_that_stayed(redis_url):
    async def go():
        store = RedisStreams(redis_url, idle_s=30, prefix="t1:")
        kept, sent = _tracker_after_frames(10), _tracker_after_frames(10)
        assert await store.load("or1") is None
        assert await store.save("or1", None, {"tracker": sent, "frames": 10}) == 0
        version, state = await store.load("or1")
        await store.aclose()
        return version, state, kept

    version, state, kept = run(go())
    assert version == 0 and state["frames"] == 10
    joints = np.random.default_rng(0).normal(0, 1000, (3, 1, 3)) + np.random.default_rng(0).normal(
        0, 200, (3, 10, 3)
    )
    a = state["tracker"].update(joints + 55.0, np.full((3, 10), 30.0), 11 / 15)
    b = kept.update(joints + 55.0, np.full((3, 10), 30.0), 11 / 15)
    assert [p.track_id for p in a] == [p.track_id for p in b]
    np.testing.assert_array_equal(np.stack([p.joints for p in a]), np.stack([p.joints for p in b]))


def test_a_write_from_a_stale_read_is_refused(redis_url):
    async def go():
        store = RedisStreams(redis_url, idle_s=30, prefix="t2:")
        await store.save("s", None, {"frames": 1})
        await store.save("s", 0, {"frames": 2})
        with pytest.raises(StaleState):
            await store.save("s", 0, {"frames": 2})  # another replica read version 0 too
        with pytest.raises(StaleState):
            await store.save("s", None, {"frames": 1})  # and one that thought the stream new
        version, state = await store.load("s")
        await store.aclose()
        return version, state

    assert run(go()) == (1, {"frames": 2})


def test_a_stream_expires_after_its_idle_time_and_is_counted_until_then(redis_url):
    async def go():
        store = RedisStreams(redis_url, idle_s=0.3, prefix="t3:")
        await store.save("a", None, {"frames": 1})
        await store.save("b", None, {"frames": 1})
        held = await store.active()
        await asyncio.sleep(0.5)
        out = held, await store.active(), await store.load("a")
        await store.aclose()
        return out

    assert run(go()) == (2, 0, None)


def test_the_lock_lets_one_frame_of_a_stream_in_at_a_time(redis_url):
    async def go():
        a = RedisStreams(redis_url, idle_s=30, prefix="t4:")
        b = RedisStreams(redis_url, idle_s=30, prefix="t4:")  # another replica
        order = []

        async def frame(store, name, hold_s):
            async with store.hold("s", wait_s=5):
                order.append(f"{name} in")
                await asyncio.sleep(hold_s)
                order.append(f"{name} out")

        await asyncio.gather(frame(a, "a", 0.2), frame(b, "b", 0.0))
        async with a.hold("s", wait_s=1):
            with pytest.raises(TimeoutError):
                async with b.hold("s", wait_s=0.1):
                    pass
        await a.aclose(), await b.aclose()
        return order

    order = run(go())
    assert order in (["a in", "a out", "b in", "b out"], ["b in", "b out", "a in", "a out"])


def test_delete_returns_the_last_state_once(redis_url):
    async def go():
        store = RedisStreams(redis_url, idle_s=30, prefix="t5:")
        await store.save("s", None, {"frames": 3})
        out = await store.delete("s"), await store.delete("s"), await store.active()
        await store.aclose()
        return out

    assert run(go()) == ({"frames": 3}, None, 0)
