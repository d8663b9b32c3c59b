"""The skeleton: MVOR's joint order and bones, left/right pairs, flip permutation, report groups."""

from __future__ import annotations

from conftest import MVOR_CATEGORY

from posenet.skeleton import (
    BONES,
    FLIP_PERMUTATION,
    JOINT_COLOURS,
    JOINT_INDEX,
    JOINT_TYPES,
    JOINTS,
    LEFT_RIGHT_PAIRS,
    NUM_JOINTS,
    SUPPORT_TYPES,
)


def test_joint_order_is_mvors() -> None:
    assert NUM_JOINTS == 10
    assert list(JOINTS) == MVOR_CATEGORY["keypoints"]
    assert all(JOINTS[JOINT_INDEX[name]] == name for name in JOINTS)


def test_bones_are_mvors_skeleton() -> None:
    expected = {tuple(sorted((a - 1, b - 1))) for a, b in MVOR_CATEGORY["skeleton"]}
    assert {tuple(sorted(b)) for b in BONES} == expected
    assert len(BONES) == len(expected)  # no duplicates


def test_bones_form_one_tree() -> None:
    # 10 joints, 9 bones would be a tree; MVOR adds the hip-hip bone, closing one loop. All joints connect.
    reached, frontier = {0}, [0]
    while frontier:
        j = frontier.pop()
        for a, b in BONES:
            for x, y in ((a, b), (b, a)):
                if x == j and y not in reached:
                    reached.add(y)
                    frontier.append(y)
    assert reached == set(range(NUM_JOINTS))


def test_left_right_pairs_match_names() -> None:
    for left, right in LEFT_RIGHT_PAIRS:
        assert JOINTS[left].startswith("left_") and JOINTS[right].startswith("right_")
        assert JOINTS[left][5:] == JOINTS[right][6:]
    paired = {j for pair in LEFT_RIGHT_PAIRS for j in pair}
    assert {j for j, name in enumerate(JOINTS) if name.startswith(("left_", "right_"))} == paired


def test_flip_permutation_is_an_involution_swapping_sides() -> None:
    assert sorted(FLIP_PERMUTATION) == list(range(NUM_JOINTS))
    assert all(FLIP_PERMUTATION[FLIP_PERMUTATION[j]] == j for j in range(NUM_JOINTS))
    for j, name in enumerate(JOINTS):
        flipped = JOINTS[FLIP_PERMUTATION[j]]
        assert flipped == name.replace("left_", "@").replace("right_", "left_").replace("@", "right_")


def test_flip_maps_bones_to_bones() -> None:
    bones = {tuple(sorted(b)) for b in BONES}
    assert {tuple(sorted((FLIP_PERMUTATION[a], FLIP_PERMUTATION[b]))) for a, b in BONES} == bones


def test_joint_types_partition_the_joints() -> None:
    members = [j for joints in JOINT_TYPES.values() for j in joints]
    assert sorted(members) == list(range(NUM_JOINTS))
    for name, joints in JOINT_TYPES.items():
        assert all(name in JOINTS[j] for j in joints)
    assert list(JOINT_TYPES) == [
        "head",
        "neck",
        "shoulder",
        "hip",
        "elbow",
        "wrist",
    ]  # the paper's column order
    assert SUPPORT_TYPES == ("shoulder", "hip", "elbow", "wrist")


def test_colours() -> None:
    assert len(JOINT_COLOURS) == NUM_JOINTS
    assert all(len(c) == 3 and all(0 <= x <= 255 for x in c) for c in JOINT_COLOURS)
