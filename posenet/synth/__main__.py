"""Render a synthetic OR RGB-D dataset in MVOR's layout and schema.

Procedural scenes on a new random rig per day (4 days, 200 frames):
    python -m posenet.synth --out data/synth_random --scenes 200 --rig random --seed 0 --workers 2
Procedural scenes seen by MVOR's real rig:
    python -m posenet.synth --out data/synth_mvorrig --scenes 200 --rig mvor
The MVOR twin (all 732 real frames, real rig, real 3D poses):
    python -m posenet.synth --out data/mvor_twin --from-mvor ../shared/mvor/camma_mvor_2018.json
    --workers 2
The unseen-look test set (the same frames, another renderer's look; never train on it):
    python -m posenet.synth --out data/mvor_alt --from-mvor ../shared/mvor/camma_mvor_2018.json --look alt
The second unseen-look test set (the alt renderer with anny mesh bodies; never train or tune on it either):
    python -m posenet.synth --out data/mvor_altmesh --from-mvor ../shared/mvor/camma_mvor_2018.json --look alt-mesh
Training scenes with hard negatives (coats, gowns on stands, apron racks, stools, equipment towers; never annotated):
    python -m posenet.synth --out data/synth_hn --scenes 200 --rig mvor --look random --mesh-share 0.5 --hard-negatives 3
A sequence (60 frames at 15 fps, 3 clinicians walking around the table, MVOR's rig):
    python -m posenet.synth --out data/seq_mvorrig --sequence --frames 60 --persons 3 --rig mvor
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import asdict
from pathlib import Path

from posenet.synth.hard_negatives import KINDS as HARD_NEGATIVE_KINDS
from posenet.synth.looks import (
    BODY_PARTS,
    DRAWN_GOWN_SHARE,
    GRAMMAR_SHARE,
    HARD_NEGATIVES,
    LOOKS,
    MESH_SHARE,
    PARTS,
)
from posenet.synth.writer import (
    ANNOTATIONS,
    MIN_KEYPOINTS_IN_IMAGE,
    MIN_KEYPOINTS_VISIBLE,
    SynthConfig,
    generate,
)

DEFAULT_MVOR = Path(__file__).resolve().parents[2] / ".." / "shared" / "mvor" / "camma_mvor_2018.json"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m posenet.synth",
        description="Render synthetic multi-view RGB-D operating-room frames (colour PNG, uint16 depth PNG "
        "in mm, 640x480) with MVOR-format annotations: person boxes of the visible pixels, 2D keypoints with "
        "visibility, 3D joints in camera 0's frame, recording days as the split unit. Prints a summary as "
        "JSON at the end.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__,
    )
    p.add_argument(
        "--out", required=True, help="output folder (annotations.json and dayD/camC/{color,depth}/)"
    )
    src = p.add_argument_group("what to render (one of)")
    src.add_argument(
        "--from-mvor",
        metavar="ANNOTATIONS.json",
        help="MVOR twin: one frame per real MVOR frame, with its rig and 3D poses",
    )
    src.add_argument("--scenes", type=int, help="procedural: this many frames, split evenly over --days")
    src.add_argument(
        "--sequence",
        action="store_true",
        help="sequences: persons walk around the table, work at it, enter and leave; one sequence of "
        "--frames frames per day, stable person ids, each frame with its sequence, frame_index and timestamp_s",
    )
    proc = p.add_argument_group("procedural scenes")
    proc.add_argument(
        "--rig",
        choices=("random", "mvor"),
        default="random",
        help="random: a new ceiling-mounted 2-4 camera rig per day; mvor: MVOR's real three cameras",
    )
    proc.add_argument(
        "--days",
        type=int,
        default=None,
        help="recording days (the cross-validation unit; default 4, or 1 sequence with --sequence)",
    )
    proc.add_argument(
        "--views", type=int, default=None, help="cameras per random rig (default: 2 to 4 per day)"
    )
    seq = p.add_argument_group("sequences (--sequence)")
    seq.add_argument("--frames", type=int, default=60, help="frames per sequence")
    seq.add_argument("--fps", type=float, default=15.0, help="frame rate")
    seq.add_argument("--persons", type=int, default=3, help="clinicians per sequence")
    p.add_argument(
        "--mvor-annotations",
        default=os.environ.get("MVOR_ANNOTATIONS", str(DEFAULT_MVOR)),
        help="MVOR json used by --rig mvor (default: $MVOR_ANNOTATIONS or ../shared/mvor/)",
    )
    p.add_argument("--limit", type=int, default=None, help="twin: render only the first N MVOR frames")
    p.add_argument("--stride", type=int, default=1, help="twin: render every K-th MVOR frame (quick checks)")
    p.add_argument(
        "--mvor-days",
        type=int,
        nargs="+",
        metavar="D",
        help="twin: render only these MVOR days, e.g. 1 2 3 for a training set that never holds day 4's poses",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="same seed, same bytes (per-frame seeds from seed/day/frame)"
    )
    p.add_argument(
        "--look",
        choices=LOOKS,
        default=None,
        help="twin: the renderer's original look; random: bodies, clothing, light, camera, depth sensor and "
        "occluders drawn per scene and person (to train on); alt: one fixed other look, never trained on; "
        "mesh: the random look with every body an anny mesh (needs the 'mesh' extra; docs/synth.md); "
        "alt-mesh: the alt look with anny mesh bodies, the second fixed look never trained or tuned on "
        "(default: random for --scenes, twin for --from-mvor, whose numbers it reproduces)",
    )
    p.add_argument(
        "--look-parts",
        nargs="+",
        choices=PARTS + BODY_PARTS,
        default=None,
        metavar="PART",
        help=f"take only these parts of --look and render the rest as the twin does ({', '.join(PARTS)}); "
        "e.g. --look alt --look-parts depth is the twin seen by the alt look's depth sensor "
        "(benchmarks/look_factors.py; default: the whole look); body:REGION takes one region of the look's body "
        "(head, trunk, arms, legs, gown) onto the twin's",
    )
    p.add_argument(
        "--grammar-share",
        type=float,
        default=GRAMMAR_SHARE,
        metavar="F",
        help="random look: the share of people whose body the body grammar builds (other kinds of trunk, limbs "
        f"and head; docs/synth.md); the rest get the twin's construction in drawn sizes (default {GRAMMAR_SHARE})",
    )
    p.add_argument(
        "--drawn-gowns",
        type=float,
        default=DRAWN_GOWN_SHARE,
        metavar="F",
        help="random look: the share of people whose gown (when their outfit has one) is of a drawn cut, a cone "
        "of drawn height, flare and length, whatever builds their body; the rest wear their body model's own "
        f"skirt (default {DRAWN_GOWN_SHARE}: as before)",
    )
    p.add_argument(
        "--mesh-share",
        type=float,
        default=MESH_SHARE,
        metavar="F",
        help="random look: the share of people drawn as anny mesh bodies (shaped, posed and dressed; needs the "
        f"'mesh' extra), drawn after everything else of a person (default {MESH_SHARE}: as before; 0.5 is the "
        "intended training share; --look mesh is a share of 1)",
    )
    p.add_argument(
        "--hard-negatives",
        type=int,
        default=HARD_NEGATIVES,
        metavar="N",
        help="random and mesh looks: try to place N hard negatives per frame (per sequence with --sequence) along "
        f"the walls, things a detector takes for people and never annotated ({', '.join(HARD_NEGATIVE_KINDS)}), "
        f"drawn after everything else (default {HARD_NEGATIVES}: as before; 3 is the intended training value)",
    )
    p.add_argument(
        "--annotate",
        choices=ANNOTATIONS,
        default="mvor",
        help="procedural scenes and sequences: mvor (default) annotates a boxed person in a view as MVOR's "
        f"annotators did, only with at least {MIN_KEYPOINTS_IN_IMAGE} of the 10 joints in the image and "
        f"{MIN_KEYPOINTS_VISIBLE} visible (else a box-only person there, and without such a view no 3D pose); "
        "all annotates every boxed person (the files of renderer version 1.1). The twin follows MVOR's own boxes",
    )
    p.add_argument("--workers", type=int, default=1, help="frames rendered in parallel processes")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def config_from_args(args: argparse.Namespace) -> SynthConfig:
    if (args.from_mvor is not None) + (args.scenes is not None) + args.sequence != 1:
        raise SystemExit("error: give exactly one of --from-mvor ANNOTATIONS.json, --scenes N or --sequence")
    if args.hard_negatives < 0:
        raise SystemExit(
            f"error: --hard-negatives must be 0 or more (objects per frame), got {args.hard_negatives}"
        )
    look = args.look or ("twin" if args.from_mvor is not None else "random")
    if args.hard_negatives and look not in ("random", "mesh"):
        raise SystemExit(
            f"error: --hard-negatives draws into the random and mesh looks only (--look {look} is fixed); add "
            "--look random or --look mesh"
        )
    if args.from_mvor is not None:
        return SynthConfig(
            out=args.out,
            mode="twin",
            rig="mvor",
            seed=args.seed,
            workers=args.workers,
            mvor_annotations=args.from_mvor,
            limit=args.limit,
            stride=args.stride,
            mvor_days=args.mvor_days,
            look=args.look or "twin",
            look_parts=args.look_parts,
            grammar_share=args.grammar_share,
            drawn_gowns=args.drawn_gowns,
            mesh_share=args.mesh_share,
            hard_negatives=args.hard_negatives,
        )
    # Procedural scenes and sequences: the same procedural world, one frame at a time or over time.
    common = dict(
        out=args.out,
        rig=args.rig,
        views=args.views,
        seed=args.seed,
        workers=args.workers,
        mvor_annotations=args.mvor_annotations if args.rig == "mvor" else None,
        look=args.look or "random",
        look_parts=args.look_parts,
        grammar_share=args.grammar_share,
        drawn_gowns=args.drawn_gowns,
        mesh_share=args.mesh_share,
        hard_negatives=args.hard_negatives,
        annotate=args.annotate,
    )
    if args.sequence:
        return SynthConfig(
            mode="sequence",
            days=args.days or 1,
            frames=args.frames,
            fps=args.fps,
            persons=args.persons,
            **common,
        )
    return SynthConfig(mode="procedural", scenes=args.scenes, days=args.days or 4, **common)


MVOR_HELP = (
    "MVOR's annotation file camma_mvor_2018.json (CC BY-NC-SA 4.0, Srivastav et al., MICCAI-LABELS 2018) "
    "holds the real rig; get it from the MVOR repository, https://github.com/CAMMA-public/MVOR, and pass "
    "its path with {flag} (or set $MVOR_ANNOTATIONS). Without it, --rig random renders procedural scenes "
    "on random rigs."
)


def _require_mvor(path: str | None, flag: str) -> None:
    """Exit with where to get MVOR's annotation file when ``path`` is not a file."""
    if not path or not Path(path).is_file():
        raise SystemExit(f"error: MVOR annotation file not found: {path!r}. " + MVOR_HELP.format(flag=flag))


def main(argv: list[str] | None = None) -> dict:
    args = build_parser().parse_args(argv)
    cfg = config_from_args(args)
    if cfg.mode == "twin":
        _require_mvor(cfg.mvor_annotations, "--from-mvor")
    elif cfg.rig == "mvor":
        _require_mvor(cfg.mvor_annotations, "--mvor-annotations")
    summary = generate(cfg, progress=not args.quiet)
    with open(Path(cfg.out) / "synth_config.json", "w") as f:
        json.dump({"config": asdict(cfg), "summary": summary}, f, indent=2)
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
