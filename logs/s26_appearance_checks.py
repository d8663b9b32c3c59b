"""posenet.appearance: a person's colour histogram reads the person (not what is behind them), and its distance."""

from __future__ import annotations

import cv2
import numpy as np

from posenet.appearance import APPEARANCE_SIZE, appearance_distance, box_histogram, person_appearance
from posenet.scene import SceneView


def _view(person_rgb, behind_rgb, person_mm=2000, behind_mm=5000) -> SceneView:
    """A 120 x 160 view: a person (columns 40-79) in front of a wall; the wall also fills the box's other half."""
    color = np.zeros((120, 160, 3), np.uint8)
    depth = np.zeros((120, 160), np.uint16)
    color[:], depth[:] = behind_rgb, behind_mm
    color[:, 40:80], depth[:, 40:80] = person_rgb, person_mm
    return SceneView(color, depth, None)


def _bin(rgb) -> int:
    """The histogram bin of a colour (hue x saturation), as OpenCV's HSV places it."""
    h, s, _ = cv2.cvtColor(np.uint8([[rgb]]), cv2.COLOR_RGB2HSV)[0, 0]
    return int(h) * 12 // 180 * 4 + int(s) * 4 // 256


def test_the_histogram_counts_the_person_and_not_the_wall_behind():
    red, blue = (200, 30, 30), (30, 30, 200)
    view = _view(red, blue)
    box = (20, 0, 100, 119)  # the middle half of it (40-80) is the person; the rest, the wall, is left out
    h = box_histogram(view.color, view.depth, box)
    assert h.shape == (APPEARANCE_SIZE,) and np.isclose(h.sum(), 1)
    assert h[_bin(red)] == 1.0
    wide = (10, 0, 129, 119)  # its middle half (40-99): two thirds person, a third wall
    assert np.isclose(
        box_histogram(view.color, view.depth, wide)[_bin(red)], 1.0
    )  # the wall, 3 m behind: left out
    near = _view(red, blue, person_mm=2000, behind_mm=2100)  # a wall 10 cm behind is taken for the person
    assert np.isclose(box_histogram(near.color, near.depth, wide)[_bin(blue)], 1 / 3)


def test_a_person_is_the_mean_over_their_views_and_unknown_without_any():
    red, green = (200, 30, 30), (30, 200, 30)
    views = [_view(red, (0, 0, 0)), _view(green, (0, 0, 0)), _view(red, (0, 0, 0))]
    box = (20, 0, 100, 119)
    look = person_appearance(views, [box, box, None])
    assert np.isclose(look[_bin(red)], 0.5) and np.isclose(look[_bin(green)], 0.5)
    assert np.isnan(person_appearance(views, [None, None, None])).all()
    no_depth = SceneView(views[0].color, np.zeros_like(views[0].depth), None)
    assert np.isnan(person_appearance([no_depth], [box])).all()
    assert np.isnan(person_appearance([SceneView(None, views[0].depth, None)], [box])).all()


def test_the_distance_is_zero_for_one_look_one_for_looks_without_a_common_bin():
    rng = np.random.default_rng(0)
    a, b = rng.dirichlet(np.ones(APPEARANCE_SIZE), 2)
    assert np.isclose(appearance_distance(a, a), 0, atol=1e-6)
    assert np.isclose(appearance_distance(a, b), appearance_distance(b, a))
    assert 0 < appearance_distance(a, b) < 1
    one, other = np.eye(APPEARANCE_SIZE)[[0, 5]]
    assert np.isclose(appearance_distance(one, other), 1)
    assert np.isnan(appearance_distance(a, np.full(APPEARANCE_SIZE, np.nan)))
    assert appearance_distance(a[None], np.stack([a, b])).shape == (2,)
