"""Streams across replicas, for real: Redis, two uvicorn replicas behind nginx (docker/nginx.conf), one killed.

A rendered sequence is streamed through nginx, which spreads the frames over both replicas; halfway, one replica
is killed. Every frame must be answered once, in order, with the track ids and smoothed joints a single server
gives the same frames, and a frame sent again after its answer was lost gets that answer back.
Skips where Debian's redis-server or nginx is missing (``.ci/run`` installs them).
"""

from __future__ import annotations

import httpx
import numpy as np
import pytest
from redis_harness import balancer, redis_server
from service_harness import Server, form_kwargs, reference_box_env

from posenet.data.mvor import MvorDataset, load_annotations
from posenet.synth.__main__ import main as synth
from service.client import scene_request

FRAMES = 10
RELAXED = {  # tiny random-init weights: wide, folded skeletons, tracked all the same (as tests/service/test_streams)
    "ORPOSE_TRACK_MAX_SPREAD_MM": "5000",
    "ORPOSE_TRACK_MIN_TORSO_MM": "0",
    "ORPOSE_TRACK_MIN_HEIGHT_MM": "0",
    "ORPOSE_TRACK_LYING_HEIGHT_MM": "0",
    "ORPOSE_TRACK_STATIC_SCENE": "0",
}


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    root = tmp_path_factory.mktemp("sequence")
    synth(["--out", str(root), "--sequence", "--frames", str(FRAMES), "--persons", "2", "--views", "2",
           "--fps", "10", "--seed", "3", "--quiet"])  # fmt: skip
    gt = load_annotations(root / "annotations.json")
    ds = MvorDataset(None, gt)
    times = [mv["timestamp_s"] for mv in gt["multiview_images"]]

    def form(k: int) -> dict:
        kwargs = form_kwargs(*scene_request(ds[k], root, True))
        kwargs["data"]["timestamp_s"] = str(times[k])
        return kwargs

    return form


def tracks(answer: dict) -> dict:
    return {
        p["id"]: (p["track_id"], [j["position"] for j in p["smoothed_joints"]]) for p in answer["persons"]
    }


def test_a_stream_goes_on_across_replicas_when_one_is_killed(tmp_path_factory, sequence):
    folder = tmp_path_factory.mktemp("scale")
    env = {**reference_box_env(folder), **RELAXED}
    with redis_server(folder) as redis_url:
        shared = {**env, "ORPOSE_REDIS_URL": redis_url}
        with Server(env) as single, httpx.Client(base_url=single, timeout=60) as client:
            reference = [client.post("/streams/ref/frames", **sequence(k)).json() for k in range(FRAMES)]
        a_server = Server(shared)
        with a_server as a_url, Server(shared) as b_url:
            replicas = [u.removeprefix("http://") for u in (a_url, b_url)]
            with balancer(folder, replicas) as lb_url:
                answers, seen_by = [], []
                with httpx.Client(base_url=lb_url, timeout=60) as lb:
                    for k in range(FRAMES):
                        if k == FRAMES // 2:  # replica A dies mid-stream
                            a_server.proc.kill()
                            a_server.proc.wait(10)
                        r = lb.post("/streams/lb/frames", **sequence(k))
                        assert r.status_code == 200, (k, r.text)
                        answers.append(r.json())
                        seen_by.append(r.headers.get("x-orpose-upstream"))
                    # A client whose answer was lost sends the frame again: it gets the same answer, not a 409.
                    again = lb.post("/streams/lb/frames", **sequence(FRAMES - 1))
                    assert again.status_code == 200, again.text
                    assert tracks(again.json()) == tracks(answers[-1])
                    assert again.json()["stream"] == answers[-1]["stream"]
    assert [a["status"] for a in answers] == ["answered"] * FRAMES
    assert [a["stream"]["frames"] for a in answers] == list(
        range(1, FRAMES + 1)
    )  # none lost, none taken twice
    assert (
        len(set(seen_by[: FRAMES // 2])) == 2
    )  # both replicas took frames of the one stream before the kill
    for got, want in zip(answers, reference, strict=True):
        g, w = tracks(got), tracks(want)
        assert {i: t for i, (t, _) in g.items()} == {i: t for i, (t, _) in w.items()}
        for i in g:
            np.testing.assert_allclose(g[i][1], w[i][1], atol=1e-3)
