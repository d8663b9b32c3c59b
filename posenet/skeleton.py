"""The MVOR upper-body skeleton: 10 joints, their bones, left/right pairs and the report groups.

Joint order is MVOR's (``categories[0].keypoints``). MVOR's ``keypoints3D`` hold 12 points; the last two (hands,
about 9 cm beyond the wrists) are not part of this skeleton and are dropped by the readers.
"""

from __future__ import annotations

JOINTS: tuple[str, ...] = (
    "head",
    "neck",
    "left_shoulder",
    "right_shoulder",
    "left_hip",
    "right_hip",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)
NUM_JOINTS = len(JOINTS)
JOINT_INDEX = {name: i for i, name in enumerate(JOINTS)}

# MVOR's categories[0].skeleton, converted from 1-based to 0-based joint indices.
BONES: tuple[tuple[int, int], ...] = (
    (0, 1), (1, 3), (3, 7), (3, 5), (7, 9), (1, 2), (2, 4), (2, 6), (6, 8), (4, 5),
)  # fmt: skip

# A typical adult's bone lengths in mm, in the order of BONES: the medians over the 1,061 3D poses of the real MVOR
# annotation (camma_mvor_2018.json), left and right averaged. Only their proportions are used (pipeline.track
# scales them to each person).
BONE_TEMPLATE_MM: tuple[float, ...] = (116.0, 190.5, 251.0, 409.0, 188.0, 190.5, 409.0, 251.0, 188.0, 320.0)

LEFT_RIGHT_PAIRS: tuple[tuple[int, int], ...] = ((2, 3), (4, 5), (6, 7), (8, 9))


def _flip_permutation() -> tuple[int, ...]:
    perm = list(range(NUM_JOINTS))
    for left, right in LEFT_RIGHT_PAIRS:
        perm[left], perm[right] = right, left
    return tuple(perm)


# FLIP_PERMUTATION[j] is the joint that j becomes in a horizontally mirrored image. It is its own inverse.
FLIP_PERMUTATION: tuple[int, ...] = _flip_permutation()

# Joint types used by the paper's tables: left and right are averaged into one type.
JOINT_TYPES: dict[str, tuple[int, ...]] = {
    "head": (0,),
    "neck": (1,),
    "shoulder": (2, 3),
    "hip": (4, 5),
    "elbow": (6, 7),
    "wrist": (8, 9),
}
# The MVOR per-support convention (Kadkhodamohammadi 2017) leaves out head and neck.
SUPPORT_TYPES: tuple[str, ...] = ("shoulder", "hip", "elbow", "wrist")

# Colours (RGB, 0-255) for drawing: left blue-ish, right red-ish, centre green.
JOINT_COLOURS: tuple[tuple[int, int, int], ...] = (
    (40, 180, 40), (40, 180, 40), (40, 90, 230), (230, 60, 40), (40, 90, 230),
    (230, 60, 40), (40, 140, 255), (255, 120, 40), (0, 200, 255), (255, 180, 0),
)  # fmt: skip
