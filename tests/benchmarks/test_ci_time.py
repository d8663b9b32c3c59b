"""benchmarks/ci_time.py: pytest's duration report is read per test (a moved test is the same test) and compared."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
from ci_time import compare, durations_of, format_table  # noqa: E402

BEFORE = """
============================= slowest durations ==============================
12.50s call     tests/posenet/test_track.py::test_ids_stay[3-True]
0.50s setup    tests/posenet/test_track.py::test_ids_stay[3-True]
2.00s call     tests/service/test_app.py::test_health
0.01s teardown tests/service/test_app.py::test_health
1.00s call     tests/posenet/test_old.py::test_removed
3 passed in 16.01s
"""
AFTER = """
13.00s call     tests/pipeline/test_track.py::test_ids_stay[3-True]
2.50s call     tests/service/test_app.py::test_health
4.00s call     tests/service/test_new.py::test_added
3 passed in 19.50s
"""


def test_durations_sum_the_phases_of_each_test_and_ignore_the_rest():
    d = durations_of(BEFORE)
    assert d == {"test_ids_stay[3-True]": 13.0, "test_health": 2.01, "test_removed": 1.0}


def test_a_moved_test_is_compared_with_itself_and_new_tests_are_counted_apart():
    before = {"commit": "a", "wall_s": 16.0, "summary": "3 passed", "durations": durations_of(BEFORE)}
    after = {"commit": "b", "wall_s": 19.5, "summary": "3 passed", "durations": durations_of(AFTER)}
    cmp = compare(before, after)
    assert cmp["common_tests"] == 2
    assert (cmp["common_before_s"], cmp["common_after_s"]) == (15.0, 15.5)
    assert (cmp["only_before"], cmp["only_before_s"], cmp["only_after"], cmp["only_after_s"]) == (
        1,
        1.0,
        1,
        4.0,
    )
    assert cmp["grew_most"][0] == ("test_health", 2.0, 2.5)
    table = format_table(before, after, cmp)
    assert "| the 2 tests at both commits (s) | 15.0 | 15.5 |" in table
