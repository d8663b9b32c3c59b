"""A stream's turns (``service.streams.Turn``): one frame at a time, in arrival order, and of the frames waiting
only the newest waits on, so that a stream sent faster than it is answered drops frames instead of queueing them.
"""

from __future__ import annotations

import anyio
import pytest

from service.streams import Dropped, Turn


async def _run(arrivals: list[float], hold_s: float = 0.05) -> tuple[list[float], dict[float, Dropped]]:
    """Frames at the times ``arrivals`` take one turn, arriving 5 ms apart, each holding it ``hold_s``; returns
    the times that ran, in the order they ran, and the dropped ones."""
    turn, ran, dropped = Turn("pose"), [], {}

    async def frame(t: float) -> None:
        try:
            async with turn.take(t):
                ran.append(t)
                await anyio.sleep(hold_s)
        except Dropped as drop:
            dropped[t] = drop

    async with anyio.create_task_group() as tg:
        for t in arrivals:
            tg.start_soon(frame, t)
            await anyio.sleep(0.005)
    assert not turn.busy and turn.waiting is None  # free again once every frame is done
    return ran, dropped


def test_frames_faster_than_the_turn_drop_the_older_waiting_one_and_the_newest_always_runs():
    ran, dropped = anyio.run(_run, [0.0, 1.0, 2.0, 3.0, 4.0])
    # 0 runs at once; 1, 2, 3 each wait in turn and are replaced by the next; 4 is the newest and runs
    assert ran == [0.0, 4.0]
    assert sorted(dropped) == [1.0, 2.0, 3.0]
    for t, drop in dropped.items():
        assert drop.newer_s == t + 1.0
        assert "faster than the server answers" in drop.reason and "pose stage" in drop.reason


def test_frames_slower_than_the_turn_all_run_in_order():
    ran, dropped = anyio.run(_run, [0.0, 1.0, 2.0], 0.001)
    assert ran == [0.0, 1.0, 2.0] and not dropped


def test_a_waiting_frame_cancelled_leaves_the_turn_to_the_others():
    async def main() -> list[float]:
        turn, ran = Turn("front"), []

        async def frame(t: float, hold: float) -> None:
            async with turn.take(t):
                ran.append(t)
                await anyio.sleep(hold)

        async with anyio.create_task_group() as tg:
            tg.start_soon(frame, 0.0, 0.05)
            await anyio.sleep(0.005)
            with anyio.move_on_after(0.01):  # a client gone while its frame waited
                await frame(1.0, 0.0)
            tg.start_soon(frame, 2.0, 0.0)
        assert not turn.busy and turn.waiting is None
        return ran

    assert anyio.run(main) == [0.0, 2.0]


@pytest.mark.parametrize("hold_s", [0.0, 0.02])
def test_at_most_one_frame_holds_the_turn(hold_s):
    async def main() -> int:
        turn, holding, most = Turn("pose"), 0, 0

        async def frame(t: float) -> None:
            nonlocal holding, most
            try:
                async with turn.take(t):
                    holding += 1
                    most = max(most, holding)
                    await anyio.sleep(hold_s)
                    holding -= 1
            except Dropped:
                pass

        async with anyio.create_task_group() as tg:
            for t in range(20):
                tg.start_soon(frame, float(t))
                await anyio.sleep(0)
        return most

    assert anyio.run(main) == 1
