"""Streams: a client's frames over time, each answered with its persons' tracks (``pipeline.track.Tracker``).

A stream is named by the client (``POST /streams/{stream_id}/frames``) and starts with its first frame. Each
frame goes through the same form reading, validation and pipeline as ``POST /scenes``
(``service.routes.scene_result``); then the stream's tracker links its persons to tracks, and the response
adds a ``track_id`` and the smoothed joints to every person.

- **Order.** Each frame must be later than the last one the stream took: an older or equal time is a 409 that says
  what was expected. A frame later than that but not later than one the stream is taking now (sent before it, it
  was overtaken on the way in) is answered as dropped. A rejected frame (4xx) leaves the stream as it was; a
  stream whose first frame is rejected is not started.
- **Two stages that overlap.** A frame goes through two :class:`Turn` s of its stream, each one frame at a time
  in arrival order: the *front* (decoding, validation and the detector, on the app's front worker) and the
  *pose* stage (grouping, the pose network, the tracker's update, on the inference worker). So frame t+1 is
  decoded and detected while frame t is in the pose stage, each stage on its own core.
- **Bounded lag.** Of the frames waiting for a turn only the newest waits on: when a newer frame arrives (for
  the front) or finishes the front (for the pose stage), the older one waiting there is answered at once as
  dropped (``StreamFrameDropped``: status ``dropped``, why, and the newer frame's time) and the stream never
  takes it. A stream holds at most four requests (one running and one waiting per stage), whatever the rate
  the client sends at, so a client that sends faster than the server answers sees drops, never a growing lag.
- **Time.** A frame's time is its form field ``timestamp_s`` (seconds, on any clock that the client keeps
  for the whole stream). A stream whose first frame has none uses the server's receive time instead, counted
  from that first frame; one stream never mixes the two (409).
- **Up.** The tracker leaves persons lying down untracked when it knows the room's up direction: the scene's
  ``up`` when it gives one, else (``ORPOSE_TRACK_FLOOR_UP``) the normal of the floor seen in the frame's depth
  images (``posenet.rig.check.floor_of_frame``, some tens of ms in the pipeline's worker thread), found once per stream and
  rig and kept; a frame that shows no floor leaves the rule off, and the stream looks again
  ``FLOOR_RETRY_FRAMES`` frames later. Each response says which it used (``stream.up``).
- **Replicas.** With ``ORPOSE_REDIS_URL`` a stream's state (its tracker, clock, last frame, floor and last answer)
  lives in Redis (``service.stream_store``) instead of this process, so the replicas behind a load balancer share
  their streams: a frame's pose turn holds the stream's Redis lock, reads the state, and writes it back with its
  answer. Each replica still overlaps the stages of the frames it receives. A frame sent again with the
  ``timestamp_s`` of the stream's last frame (a client, or nginx, retrying after the replica that took it died
  before answering) gets that frame's stored answer instead of a 409. ``ORPOSE_MAX_STREAMS`` bounds each replica's
  streams, and the server clock of streams without ``timestamp_s`` is wall time, which the replicas share.
- **Bounds.** At most ``ORPOSE_MAX_STREAMS`` streams are held; one more is a 503 with Retry-After (the time
  until the least recently used idle stream expires). A stream that gets no frame for
  ``ORPOSE_STREAM_IDLE_S`` ends; expired streams are dropped whenever a stream route is called. ``DELETE
  /streams/{stream_id}`` ends one at once; a frame in progress on it is still answered.

Everything here runs on the event loop except the pipeline itself (worker threads), so the registry and the
turns need no thread lock; the tracker's update (< 1 ms) runs on the loop in the frame's pose turn.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio
import numpy as np
import torch
from fastapi import HTTPException

from pipeline.track import Tracker
from pipeline.two_stage import SceneResult, TrackerQuestions
from posenet.rig.check import floor_of_frame
from posenet.skeleton import JOINTS
from service.errors import InputError
from service.response import scene_out, serialise
from service.schemas import (
    SmoothedJoint,
    StreamEnded,
    StreamFrameDropped,
    StreamFrameOut,
    StreamState,
    StreamTimings,
    TrackedPerson,
)
from service.stream_store import RedisStreams, StaleState
from service.validation import ValidatedScene

CONFLICT = 409
STREAM_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
# Times beyond this lose sub-millisecond resolution in a float64 (and no clock of a recording reaches it: Unix
# time is 1.8e9 s).
MAX_TIMESTAMP_S = 1e11
# A stream whose frames showed no floor looks for one again after this many frames (each look costs tens of ms).
FLOOR_RETRY_FRAMES = 30


def check_stream_id(stream_id: str) -> None:
    if not STREAM_ID.fullmatch(stream_id):
        raise InputError(
            f"stream id {stream_id[:80]!r} is not valid: use 1 to 64 letters, digits, '.', '_' or '-', "
            "starting with a letter or digit (e.g. or2-sequence-1)"
        )


def parse_timestamp(text: bytes | None) -> float | None:
    """The ``timestamp_s`` form field as seconds, or None when it is absent; 422 when it is not a time."""
    if text is None:
        return None
    try:
        value = float(text.decode(errors="replace").strip())
    except ValueError:
        value = math.nan
    if not (0 <= value <= MAX_TIMESTAMP_S):  # NaN fails too
        raise InputError(
            f"timestamp_s {text[:40].decode(errors='replace')!r} is not a time: give the frame's time in seconds "
            f"as a number from 0 to {MAX_TIMESTAMP_S:.0e} (e.g. 12.067, or Unix time), or leave the field out to "
            "use the server's receive time"
        )
    return value


class Dropped(Exception):
    """A frame that a newer frame of its stream replaced while it waited for a turn; ``reason`` says so."""

    def __init__(self, reason: str, newer_s: float) -> None:
        super().__init__(reason)
        self.reason, self.newer_s = reason, newer_s


@dataclass(eq=False)
class _Ticket:
    """A frame waiting for a :class:`Turn`: woken when the turn passes to it, or when it is dropped."""

    time: float
    woken: anyio.Event = field(default_factory=anyio.Event)
    dropped: Dropped | None = None


@dataclass
class Turn:
    """One stage of a stream's frames (module docstring): one frame at a time, in arrival order, and of the frames
    waiting for it only the newest: a frame that arrives while another waits drops that one."""

    name: str  # "front" or "pose": named in a dropped frame's reason
    busy: bool = False
    waiting: _Ticket | None = None

    @asynccontextmanager
    async def take(self, time_s: float) -> AsyncIterator[float]:
        """Hold the turn for the frame at ``time_s`` (the stream's clock), yielding the ms it waited; raises
        :class:`Dropped` when a newer frame took its place while it waited."""
        t0 = time.perf_counter()
        if self.waiting is not None:
            older = self.waiting
            older.dropped = Dropped(
                f"a newer frame of this stream (at {time_s:.3f} s) arrived while this one (at {older.time:.3f} s) "
                f"waited for the {self.name} stage: frames came faster than the server answers them, and a "
                "stream answers its newest frame rather than letting a queue grow; send frames no faster than "
                "they are answered to have each one answered",
                time_s,
            )
            older.woken.set()
            self.waiting = None
        if self.busy:
            ticket = self.waiting = _Ticket(time_s)
            try:
                await ticket.woken.wait()
            except BaseException:
                if self.waiting is ticket:
                    self.waiting = None
                elif ticket.dropped is None:  # the turn had passed to it: pass it on
                    self._release()
                raise
            if ticket.dropped is not None:
                raise ticket.dropped
        else:
            self.busy = True
        try:
            yield (time.perf_counter() - t0) * 1e3
        finally:
            self._release()

    def _release(self) -> None:
        following, self.waiting = self.waiting, None
        if following is None:
            self.busy = False
        else:
            following.woken.set()  # the turn passes to it (still busy)


@dataclass
class Stream:
    """One stream's state: its tracker, the last time it took, its frames in progress, and who is using it."""

    id: str
    tracker: Tracker
    last_used: float  # the registry's clock, s: when a request last finished with it
    users: int = 0  # requests in progress: the stream does not expire under them
    frames: int = 0
    clock: str | None = None  # "client" or "server", fixed by the first frame taken
    last_time: float | None = None  # the last frame's time on that clock, s
    origin: float = 0.0  # server clock: the first frame's receive time (registry clock)
    floor: Floor | None = None  # the last look for the floor (for scenes without up)
    front: Turn = field(default_factory=lambda: Turn("front"))  # decoding and detection
    pose: Turn = field(default_factory=lambda: Turn("pose"))  # the pose stage and the tracker
    taking: list[Frame] = field(default_factory=list)  # frames admitted, not yet answered or refused
    version: int | None = (
        None  # with a shared store: the version of the state this replica holds (None: none)
    )
    last_answer: bytes | None = (
        None  # with a shared store: the last frame's answer, for a retry of that frame
    )

    # What a shared store keeps (service.stream_store): everything a replica needs to take the next frame.
    SHARED = ("tracker", "frames", "clock", "last_time", "origin", "floor", "last_answer")

    def shared(self) -> dict:
        return {name: getattr(self, name) for name in self.SHARED}


@dataclass(frozen=True)
class Floor:
    """A stream's look for the floor in a frame's depth images: the rig it was made on (the cameras' extrinsics,
    as bytes), the room's up found (3,), or None, and the stream's frame count then."""

    rig: bytes
    up: np.ndarray | None
    frames: int


def rig_key(scene: ValidatedScene) -> bytes:
    """The extrinsics of a scene's cameras as bytes: equal for frames of one rig (the floor depends on nothing
    else; the intrinsics change with the decoding size)."""
    return b"".join(v.camera.extrinsics.to(torch.float64).numpy().tobytes() for v in scene.views)


def find_up(stream: Stream, scene: ValidatedScene) -> tuple[np.ndarray | None, Floor | None, float]:
    """The room's up for a frame of ``stream`` whose scene gives none: the floor in its depth images
    (``posenet.rig.check.floor_of_frame``; call it in a worker thread), or the stream's earlier look on the same
    rig.

    Returns (up (3,) or None, the look to keep (:meth:`Frame.answer` commits it; None: nothing new), ms)."""
    rig = rig_key(scene)
    last = stream.floor
    if (
        last is not None
        and last.rig == rig
        and (last.up is not None or stream.frames - last.frames < FLOOR_RETRY_FRAMES)
    ):
        return last.up, None, 0.0
    t0 = time.perf_counter()
    found = floor_of_frame([v.camera for v in scene.views], [v.depth for v in scene.views])
    up = None if found is None else found[0].numpy()
    return up, Floor(rig, up, stream.frames), (time.perf_counter() - t0) * 1e3


class StreamRegistry:
    """The streams of one app, bounded in number and expiring when idle (module docstring).

    ``now`` is the clock of idle times and server timestamps (monotonic seconds).
    """

    def __init__(
        self,
        max_streams: int,
        idle_s: float,
        tracker: Callable[[], Tracker],
        retry_after_s: int = 1,
        now: Callable[[], float] = time.monotonic,
        floor_up: bool = True,
        unsure: bool = True,
        store: RedisStreams | None = None,
        static_scene: bool = True,
    ) -> None:
        """``floor_up``: find the room's up in the depth images for scenes without one (``ORPOSE_TRACK_FLOOR_UP``);
        ``unsure``: give the trackers the persons the detector was unsure of, when they can use them; ``store``:
        keep the streams' state in Redis, shared by the replicas (module docstring), else in this process."""
        self.floor_up, self.unsure, self.store = floor_up, unsure, store
        self.static_scene = static_scene  # give the trackers the frames' views (ORPOSE_TRACK_STATIC_SCENE)
        self.max_streams = max_streams
        self.idle_s = idle_s
        self.tracker = tracker
        self.retry_after_s = retry_after_s
        self.now = now
        self.streams: dict[str, Stream] = {}

    def _idle(self, stream: Stream, now: float) -> bool:
        """Whether ``stream`` has expired: no frame in progress and none for ``idle_s``."""
        return not stream.users and now - stream.last_used > self.idle_s

    def expire(self) -> None:
        now = self.now()
        for sid in [s.id for s in self.streams.values() if self._idle(s, now)]:
            del self.streams[sid]

    def active(self) -> int:
        """The streams held that have not expired (those ``expire`` would keep)."""
        now = self.now()
        return sum(1 for s in self.streams.values() if not self._idle(s, now))

    def open(self, stream_id: str) -> Stream:
        """The stream ``stream_id``, started if it does not exist; 503 when the registry is full."""
        self.expire()
        stream = self.streams.get(stream_id)
        if stream is not None:
            return stream
        if len(self.streams) >= self.max_streams:
            idle = [self.idle_s - (self.now() - s.last_used) for s in self.streams.values() if not s.users]
            wait = math.ceil(max(min(idle), 0.0)) + 1 if idle else self.retry_after_s
            raise HTTPException(
                503,
                f"the server already holds {self.max_streams} streams (ORPOSE_MAX_STREAMS): end one you no longer "
                f"need (DELETE /streams/{{stream_id}}), or retry after {wait} s, when the least recently used "
                f"idle stream expires (ORPOSE_STREAM_IDLE_S = {self.idle_s:g} s without a frame)",
                headers={"Retry-After": str(wait)},
            )
        stream = self.streams[stream_id] = Stream(stream_id, self.tracker(), self.now())
        return stream

    async def pull(self, stream: Stream) -> None:
        """With a shared store: bring ``stream`` up to the state stored for it (another replica may have taken its
        last frames; none stored: it ended or expired, and starts afresh)."""
        if self.store is None:
            return
        got = await self.store.load(stream.id)
        if got is None:
            if stream.version is not None:
                fresh = Stream(stream.id, self.tracker(), stream.last_used)
                for name in Stream.SHARED:
                    setattr(stream, name, getattr(fresh, name))
                stream.version = None
            return
        version, state = got
        if version != stream.version:
            for name in Stream.SHARED:
                setattr(stream, name, state[name])
            stream.version = version

    async def push(self, stream: Stream) -> None:
        """With a shared store: write the state of ``stream`` after a frame it took (under its lock)."""
        if self.store is None:
            return
        try:
            stream.version = await self.store.save(stream.id, stream.version, stream.shared())
        except StaleState as exc:
            stream.version = None  # read afresh next time
            raise HTTPException(
                CONFLICT,
                f"{exc}: another replica took a frame of it meanwhile (its lock outlived "
                f"{self.store.lock_timeout_s:g} s); send the next frame",
            ) from exc

    async def end(self, stream_id: str) -> StreamEnded:
        """End ``stream_id`` now; 404 when there is no such stream."""
        self.expire()
        stream = self.streams.pop(stream_id, None)
        if self.store is not None:
            state = await self.store.delete(stream_id)
            if state is not None:
                return StreamEnded(id=stream_id, frames=state["frames"], tracks=state["tracker"].next_id)
            stream = None
        if stream is None:
            raise HTTPException(
                404,
                f"there is no stream {stream_id!r}: it never took a frame, was ended already, or expired after "
                f"{self.idle_s:g} s without a frame (ORPOSE_STREAM_IDLE_S)",
            )
        return StreamEnded(id=stream.id, frames=stream.frames, tracks=stream.tracker.next_id)

    @asynccontextmanager
    async def frame(self, stream_id: str, timestamp_s: float | None, received: float) -> AsyncIterator[Frame]:
        """Hold ``stream_id`` for one frame: its lock, and the frame's time checked against the stream's last.

        ``timestamp_s``: the client's time, or None for the server's; ``received``: the request's arrival on
        the registry's clock. Raises 409 when the frame is not later than the stream's last one.
        """
        stream = self.open(stream_id)
        stream.users += 1
        taken = None
        try:
            await self.pull(stream)
            if self.store is not None and timestamp_s is not None and timestamp_s == stream.last_time:
                # The stream's last frame sent again: its answer was lost on the way (module docstring).
                yield Frame(stream, timestamp_s, "client", received, replay=stream.last_answer)
                return
            clock = "server" if timestamp_s is None else "client"
            time_s, origin = _frame_time(stream, clock, timestamp_s, received)
            newer = max((f.time for f in stream.taking), default=-math.inf)
            if time_s <= newer:  # overtaken on the way in by a later frame: it can never be taken
                yield Frame(stream, time_s, clock, received, origin=origin, superseded=Dropped(
                    f"this frame (at {time_s:.3f} s) arrived after a later frame of its stream (at {newer:.3f} s), "
                    "which the stream is already taking: frames sent this close together can overtake each other "
                    "on the way, and a stream takes its frames in time order",
                    newer,
                ))  # fmt: skip
                return
            taken = Frame(
                stream, time_s, clock, received, self.floor_up, self.unsure, origin=origin, registry=self
            )
            stream.taking.append(taken)
            yield taken
        finally:
            if taken is not None:
                stream.taking.remove(taken)
            stream.users -= 1
            stream.last_used = self.now()
            if not stream.frames and not stream.users and self.streams.get(stream_id) is stream:
                # A stream whose first frame was refused was never started: it holds no place (a client's bad
                # requests cannot fill ORPOSE_MAX_STREAMS), and a DELETE of it is a 404.
                del self.streams[stream_id]


def _frame_time(
    stream: Stream, clock: str, timestamp_s: float | None, received: float
) -> tuple[float, float]:
    """The frame's time on the stream's clock and that clock's origin (the server clock's: the first frame's
    receive time); 409 unless it is later than the last frame the stream took (a frame older than one it is taking
    is answered as dropped instead: :meth:`StreamRegistry.frame`)."""
    first = stream.taking[0] if stream.clock is None and stream.taking else None
    fixed, origin = (stream.clock, stream.origin) if first is None else (first.clock, first.origin)
    last = stream.last_time if stream.clock is not None else -math.inf
    if fixed is None:  # the first frame: it fixes the clock once it is taken (Frame.answer)
        return (0.0, received) if timestamp_s is None else (timestamp_s, 0.0)
    sid = stream.id
    if clock != fixed:
        fix = "give timestamp_s with every frame" if fixed == "client" else "leave timestamp_s out"
        raise HTTPException(
            CONFLICT,
            f"stream {sid!r} takes its times from the {fixed} "
            f"({'its frames carry timestamp_s' if fixed == 'client' else 'its first frame had no timestamp_s'})"
            f", and one stream never mixes clocks: {fix}, or end the stream (DELETE /streams/{sid}) to start over",
        )
    if clock == "client":
        t = timestamp_s
        if t <= last:
            raise HTTPException(
                CONFLICT,
                f"frames of stream {sid!r} must arrive in time order: timestamp_s {t:g} is not later than its "
                f"last frame's {last:g}; expected a timestamp_s above {last:g} (send frames in time order), or "
                f"end the stream (DELETE /streams/{sid}) to start over",
            )
        return t, origin
    t = received - origin
    if t <= last:
        raise HTTPException(
            CONFLICT,
            f"this frame of stream {sid!r} arrived at {t:.3f} s (server clock, from the stream's first frame), "
            f"before its last frame ({last:.3f} s) was taken: send a stream's frames in order, or give each "
            "frame its timestamp_s",
        )
    return t, origin


@dataclass
class Frame:
    """One frame being taken by a stream (inside :meth:`StreamRegistry.frame`)."""

    stream: Stream
    time: float  # s, on the stream's clock
    clock: str  # "client" or "server"
    received: float  # the request's arrival, registry clock
    floor_up: bool = True  # look for the floor when the scene gives no up
    unsure: bool = True  # let the tracker continue tracks with persons the detector was unsure of
    up: np.ndarray | None = None  # the room's up the tracker uses (prepare: the scene's, else the floor's)
    look: Floor | None = None  # a new look for the floor, which answer() keeps
    floor_ms: float = 0.0  # what that look cost
    origin: float = 0.0  # the server clock's origin this frame's time counts from (registry clock)
    waited_ms: float = 0.0  # waiting for the stream's turns (front and pose)
    superseded: Dropped | None = None  # it arrived after a later frame of the stream: it is dropped at once
    replay: bytes | None = None  # the stream's last frame sent again: its stored answer (shared store)
    registry: StreamRegistry | None = None  # the registry that took it (its shared store, if any)

    @asynccontextmanager
    async def turn(self, stage: str) -> AsyncIterator[None]:
        """Hold the stream's ``stage`` ("front" or "pose") for this frame; raises :class:`Dropped` when a newer
        frame took this one's place while it waited, or arrived before this one (module docstring)."""
        if self.superseded is not None:
            raise self.superseded
        async with getattr(self.stream, stage).take(self.time) as waited_ms:
            self.waited_ms += waited_ms
            store = None if self.registry is None or stage != "pose" else self.registry.store
            if store is None:
                yield
                return
            async with store.hold(self.stream.id, wait_s=store.lock_timeout_s):  # one replica at a time
                await self._shared_turn()
                try:
                    yield
                except BaseException:
                    self.stream.version = None  # it may have changed here without being written: read afresh
                    raise
                await self.registry.push(self.stream)

    async def _shared_turn(self) -> None:
        """The pose turn's start with a shared store: the stream as stored, and this frame still later than the
        last one any replica took (else it is dropped: a later frame was taken elsewhere meanwhile)."""
        stream = self.stream
        await self.registry.pull(stream)
        if stream.clock is not None and self.time <= stream.last_time:
            raise Dropped(
                f"a later frame of this stream (at {stream.last_time:.3f} s) was taken by another replica while "
                f"this one (at {self.time:.3f} s) was decoded: a stream takes its frames in time order",
                stream.last_time,
            )

    def _views(self, scene: ValidatedScene):
        """The views the tracker learns the static scene from (None: ORPOSE_TRACK_STATIC_SCENE is off)."""
        return scene.views if self.registry is None or self.registry.static_scene else None

    def dropped(self, drop: Dropped, t_start: float) -> bytes:
        """The response body of this frame, dropped: nothing of the stream changed."""
        body = StreamFrameDropped(
            stream=self.stream.id, timestamp_s=self.time, clock=self.clock, reason=drop.reason,
            newer_timestamp_s=drop.newer_s, waited_ms=self.waited_ms,
            total_ms=(time.perf_counter() - t_start) * 1e3,
        )  # fmt: skip
        return body.model_dump_json().encode()

    def prepare(self, scene: ValidatedScene):
        """The frame's work before its pipeline runs, in the pipeline's worker thread (``service.routes.
        scene_result``): the room's up (the scene's, else the floor's, :func:`find_up`), and what to tell
        ``ScenePipeline.run`` about the unsure persons: list them only when the stream's tracker could give one
        a track (``Tracker.unsure_targets`` on the frame's sure persons), which it rarely can; finding them costs
        a few ms. The stream is only read here (its lock is held; it changes in :meth:`answer`)."""
        self.up = scene.up
        if self.up is None and self.floor_up:
            self.up, self.look, self.floor_ms = find_up(self.stream, scene)
        if not self.unsure:
            return False
        return TrackerQuestions.asking(self.stream.tracker, self.time, self.up)

    def answer(
        self,
        result: SceneResult,
        scene: ValidatedScene,
        decode_ms: float,
        t_start: float,
    ) -> bytes:
        """Track ``result``'s persons, commit the frame to the stream, and return the response body.

        The stream changes only here, after every check has passed, so a rejected frame leaves it as it was.
        """
        t0 = time.perf_counter()
        out = scene_out(result, scene, decode_ms)  # 422 on a non-finite estimate, before the tracker sees it
        stream = self.stream
        joints = np.array([p.joints for p in result.persons], np.float64).reshape(-1, len(JOINTS), 3)
        spread = np.array([p.spread_mm for p in result.persons], np.float64).reshape(-1, len(JOINTS))
        unsure = np.array([p.unsure for p in result.persons], bool)
        up_source = "scene" if scene.up is not None else "floor" if self.up is not None else "none"
        t_track = time.perf_counter()
        views = self._views(scene)
        tracked = stream.tracker.update(joints, spread, self.time, unsure, self.up, views=views)
        track_ms = (time.perf_counter() - t_track) * 1e3
        if stream.clock is None:
            stream.clock, stream.origin = self.clock, self.origin
        if self.look is not None:
            stream.floor = self.look
        stream.frames += 1
        stream.last_time = self.time
        # A person the detector was unsure of is answered only when it continues a track; the persons before it
        # keep their ids, and those answered after it are numbered on (detector mode's ids are indices).
        kept = [(person, t, u) for person, t, u in zip(out.persons, tracked, unsure, strict=True)
                if not u or t.track_id is not None]  # fmt: skip
        persons = [
            TrackedPerson(
                **{**person.model_dump(), **({"id": i} if u else {})},
                track_id=t.track_id,
                unsure=bool(u),
                smoothed_joints=[
                    SmoothedJoint(name=name, position=[float(x) for x in xyz])
                    for name, xyz in zip(JOINTS, t.joints, strict=True)
                ],
            )
            for i, (person, t, u) in enumerate(kept)
        ]
        body = StreamFrameOut(
            mode=out.mode,
            persons=persons,
            notes=out.notes,
            timings=StreamTimings(
                **out.timings.model_dump(),
                track=track_ms,
                background=0.0 if views is None else stream.tracker.background_ms,
                unsure=result.unsure_ms,
                floor=self.floor_ms,
                wait=self.waited_ms,
            ),
            stream=StreamState(
                id=stream.id, frames=stream.frames, timestamp_s=self.time, clock=stream.clock, up=up_source
            ),
        )
        answer = serialise(body, t0, t_start)
        if self.registry is not None and self.registry.store is not None:
            stream.last_answer = answer
        return answer
