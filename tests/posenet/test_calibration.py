"""posenet.net.calibration: the confidence is a probability, falls with the spread, and the fit recovers a known law."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from posenet.evaluation.calibrate import write_section
from posenet.net.calibration import TYPE_NAMES, TYPE_OF_JOINT, Calibration, fit, reliability
from posenet.skeleton import NUM_JOINTS

FITTED = Calibration(
    "logistic",
    100.0,
    intercept=[6.0, 5.5, 5.0, 4.5, 4.0, 3.5],
    log_spread=[-1.2, -1.1, -1.0, -0.9, -0.8, 0.0],
    views=0.3,
)


@pytest.mark.parametrize("cal", [Calibration(), FITTED], ids=["fallback", "fitted"])
def test_confidence_is_a_probability_that_falls_with_the_spread(cal):
    spread = torch.logspace(-1, 4, 200, dtype=torch.float64)[:, None].expand(200, NUM_JOINTS)  # (S, J) mm
    for views in (1, 2, 3, 4):
        conf = cal(spread, torch.full((200,), views))  # (S, J)
        assert conf.shape == (200, NUM_JOINTS) and torch.isfinite(conf).all()
        assert (conf >= 0).all() and (conf <= 1).all()
        assert (conf.diff(dim=0) <= 1e-12).all()  # never rises with the spread
    if cal.kind == "logistic":  # only a fitted slope of 0 (wrists here) is flat
        steep = [j for j in range(NUM_JOINTS) if cal.log_spread[TYPE_OF_JOINT[j]] < 0]
        assert (conf[0, steep] - conf[-1, steep] > 0.5).all()
    else:
        assert conf[0].min() > 0.999 and conf[-1].max() < 0.01


def test_fallback_is_the_maxwell_cdf():
    # spread s read as the RMS 3D error: P(|e| <= r) for a 3D Gaussian with per-axis std s / sqrt(3).
    rng = np.random.default_rng(0)
    s = 80.0
    e = np.linalg.norm(rng.normal(0, s / math.sqrt(3), (200_000, 3)), axis=1)
    conf = Calibration()(torch.full((1, NUM_JOINTS), s, dtype=torch.float64), torch.ones(1, dtype=torch.long))
    assert abs(conf[0, 0].item() - (e <= 100).mean()) < 0.005


def test_batched_equals_per_joint_and_works_in_float32():
    spread = torch.rand(3, 4, NUM_JOINTS) * 300 + 5  # (B, P, J)
    support = torch.randint(1, 4, (3, 4))
    conf = FITTED(spread, support)
    for b in range(3):
        for p in range(4):
            one = FITTED.per_joint(spread[b, p], torch.arange(NUM_JOINTS), support[b, p].expand(NUM_JOINTS))
            torch.testing.assert_close(conf[b, p], one)
    assert conf.dtype == torch.float32


def test_bad_shapes_and_non_monotone_parameters_raise():
    with pytest.raises(ValueError, match=r"\(\.\.\., 10\)"):
        FITTED(torch.ones(2, 9), torch.ones(2))
    with pytest.raises(ValueError, match="<= 0"):
        Calibration("logistic", 100.0, [0.0] * 6, [0.1] + [0.0] * 5)


def _sample(cal: Calibration, n: int, rng) -> dict:
    joint = rng.integers(0, NUM_JOINTS, n)
    support = rng.integers(1, 4, n)
    spread = np.exp(rng.uniform(np.log(10), np.log(800), n))
    p = cal.per_joint(torch.as_tensor(spread), torch.as_tensor(joint), torch.as_tensor(support)).numpy()
    hit = rng.random(n) < p
    error = np.where(hit, 50.0, 150.0)  # within / beyond the 100 mm radius
    return {"spread_mm": spread, "joint": joint, "support": support, "error_mm": error, "p": p, "hit": hit}


def test_fit_recovers_a_known_relation():
    truth = Calibration(
        "logistic", 100.0, [7.0, 6.0, 5.0, 4.0, 6.0, 3.0], [-1.5, -1.2, -1.0, -0.8, -1.3, -0.7], 0.4
    )
    data = _sample(truth, 60_000, np.random.default_rng(1))
    got = fit(data["spread_mm"], data["joint"], data["support"], data["error_mm"], ridge=1e-3)
    np.testing.assert_allclose(got.log_spread, truth.log_spread, atol=0.12)
    np.testing.assert_allclose(got.intercept, truth.intercept, atol=0.6)
    assert abs(got.views - truth.views) < 0.08
    # and on fresh data it is calibrated, while the (unfitted) fallback is not
    test = _sample(truth, 20_000, np.random.default_rng(2))
    args = [torch.as_tensor(test[k]) for k in ("spread_mm", "joint", "support")]
    assert reliability(got.per_joint(*args).numpy(), test["hit"])["ece"] < 0.02
    assert reliability(Calibration().per_joint(*args).numpy(), test["hit"])["ece"] > 0.05


def test_fit_keeps_slopes_non_positive():
    # a type where a larger spread means *more* hits (nonsense) gets a flat curve rather than a rising one
    rng = np.random.default_rng(3)
    n = 4000
    spread = rng.uniform(10, 500, n)
    joint = np.zeros(n, int)  # head only
    hit = rng.random(n) < spread / 500
    got = fit(
        spread, joint, np.ones(n, int), np.where(hit, 0.0, 200.0), ridge=1
    )  # an int ridge, other types absent
    assert got.log_spread[0] == 0.0 and all(b <= 0 for b in got.log_spread)


def test_reliability_numbers():
    conf = np.array([0.05, 0.05, 0.95, 0.95])
    rel = reliability(conf, np.array([0, 0, 1, 0]))
    assert rel["count"][0] == 2 and rel["count"][9] == 2 and rel["rate"][9] == 0.5
    assert rel["ece"] == pytest.approx(0.5 * 0.05 + 0.5 * 0.45)


def test_section_round_trip(tmp_path):
    config_file = tmp_path / "ckpt.json"
    config_file.write_text(json.dumps({"model": {"base": 16}}))
    assert Calibration.from_config(json.loads(config_file.read_text())).kind == "default"
    write_section(config_file, FITTED)
    config = json.loads(config_file.read_text())
    assert config["model"] == {"base": 16} and config["calibration"]["joint_types"] == list(TYPE_NAMES)
    back = Calibration.from_config(config)
    spread = torch.rand(5, NUM_JOINTS) * 200
    torch.testing.assert_close(back(spread, torch.ones(5)), FITTED(spread, torch.ones(5)))


def test_report_caps_one_view_skeletons_and_scores_served_confidences():
    from posenet.evaluation.calibrate import report, served_set

    joints = {"spread_mm": np.full(4, 20.0), "joint": np.array([2, 2, 3, 3]), "support": np.ones(4, int),
              "error_mm": np.array([10.0, 10.0, 300.0, 300.0]), "capped": np.array([False, False, True, True])}  # fmt: skip
    cal = Calibration(kind="logistic", intercept=[3.0] * 6, log_spread=[0.0] * 6)
    r = report({"c": cal}, joints, 100.0)["c"]  # two hits at sigmoid(3), two misses capped at 0.2
    assert r["ece"] == pytest.approx((2 * (1 - 1 / (1 + np.exp(-3))) + 2 * 0.2) / 4)
    out = report({"c": cal}, {"confidence": np.array([0.9, 0.1]), "error_mm": np.array([50.0, 500.0])}, 100.0)
    assert list(out) == ["served"] and out["served"]["ece"] == pytest.approx(0.1)
    assert served_set("data/x:4=p.json")[1:] == ([4], Path("p.json"))
