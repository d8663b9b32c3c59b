"""Cross-view matcher speed: microseconds per scene against the number of boxes.

    nice python benchmarks/matcher_speed.py [--views 3 4] [--people 1 2 4 6 8 10] [--min-seen 0.5]

Scenes: P people on a grid 0.9 m apart, seen by V ceiling-mounted cameras on a ring (the hand-made scenes of
``tests/pipeline/test_matching.py``, raised 1.5 m). A box is drawn where at least half of it shows its person
(``--min-seen 0``: all P x V boxes, the most combinations). Prints one JSON line per (V, P): the median
microseconds of ``match_boxes`` (robust depth, lifting, enumeration, greedy choice), and how many persons
came out as exactly one group holding all their boxes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_matching import render, ring_cameras  # noqa: E402

from pipeline.association import frame_association  # noqa: E402
from pipeline.matching import match_boxes  # noqa: E402


def people_grid(n: int, rng: np.random.Generator, centre_z: float) -> np.ndarray:
    """``(n, 3)`` positions (mm, camera 0's frame) on a jittered 0.9 m grid around ``(0, 0, centre_z)``."""
    side = int(np.ceil(np.sqrt(n)))
    ij = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
    xz = (ij - (side - 1) / 2) * 900.0 + rng.uniform(-100, 100, (n, 2))
    return np.stack([xz[:, 0], np.zeros(n), centre_z + xz[:, 1]], axis=1)


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--views", type=int, nargs="+", default=[3, 4])
    p.add_argument("--people", type=int, nargs="+", default=[1, 2, 4, 6, 8, 10])
    p.add_argument("--repeats", type=int, default=50)
    p.add_argument(
        "--min-seen",
        type=float,
        default=0.5,
        help="draw a box where this fraction shows its person (0: all P x V)",
    )
    args = p.parse_args(argv)
    rng = np.random.default_rng(0)
    rows = []
    for V in args.views:
        cams = ring_cameras(V, radius=5000.0, height=1500.0)  # ceiling-mounted, as in an OR
        for P in args.people:
            people = people_grid(P, rng, centre_z=5000.0)
            views = render(cams, people, min_seen=args.min_seen)
            boxes, depths = [b for b, _, _ in views], [d for _, d, _ in views]
            groups = match_boxes(boxes, depths, cams)  # warm-up
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                match_boxes(boxes, depths, cams)
                times.append(time.perf_counter() - t)
            row = {
                "views": V,
                "people": P,
                "boxes": int(sum(len(b) for b in boxes)),
                "groups": len(groups),
                # persons whose boxes form exactly one group holding all of them and nothing else
                "persons_complete": frame_association(
                    [b.astype(np.float64) for b in boxes], [i for _, _, i in views], boxes, groups
                )["complete"],
                "us_per_scene": round(1e6 * float(np.median(times))),
            }
            print(json.dumps(row))
            rows.append(row)
    return rows


if __name__ == "__main__":
    main()
