"""Import, export and check camera rigs.

    python -m posenet.rig convert --from mvor camma_mvor_2018.json --out rig.json
    python -m posenet.rig convert --from opencv-yaml intri.yml extri.yml --out rig.json [--unit m]
    python -m posenet.rig convert --from 4d-or camera01.json ... camera06.json --out rig.json
    python -m posenet.rig convert --from json cam_a.json cam_b.json --out rig.json
    python -m posenet.rig convert --to opencv-yaml rig.json --out calib/      # writes calib/intri.yml, extri.yml
    python -m posenet.rig check rig.json [--depth-frames d0.png d1.png ...] [--picture rig.png]

``rig.json`` is the list of per-view ``camera`` objects that ``POST /scenes`` takes (``posenet/rig/rigfile.py``).
Its reference frame is the first camera's, unless ``--ref world`` keeps the input's world (MVOR: the room frame of
``firstCamToRoomRef``). Every convention and unit applied is printed; units are checked against the camera spacing
and transform directions against where the cameras look, and a contradiction stops the conversion.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from posenet.cameras import rigid_inverse
from posenet.rig import formats
from posenet.rig.rigfile import Rig, read_rig_json, write_rig_json


def read_rig(fmt: str, inputs: list[Path], distortion: str | None = None, unit: str | None = None) -> Rig:
    """Read a rig in ``fmt`` from ``inputs`` (a folder is expanded to the format's files)."""
    if len(inputs) == 1 and inputs[0].is_dir():
        folder = inputs[0]
        inputs = {
            "opencv-yaml": [folder / "intri.yml", folder / "extri.yml"],
            "4d-or": sorted(folder.glob("camera0*.json")),
            "json": sorted(folder.glob("*.json")),
        }.get(fmt, inputs)
    missing = [p for p in inputs if not p.is_file()]
    if missing or not inputs:
        raise FileNotFoundError(f"input files do not exist: {[str(p) for p in missing] or '(none given)'}")
    if fmt == "mvor":
        return formats.read_mvor(inputs[0], distortion or "drop", unit)
    if fmt == "opencv-yaml":
        if len(inputs) != 2:
            raise ValueError("opencv-yaml needs two inputs, intri.yml then extri.yml (or their folder)")
        return formats.read_opencv_yaml(inputs[0], inputs[1], distortion or "keep", unit)
    if fmt == "4d-or":
        return formats.read_4dor(inputs, distortion or "drop", unit)
    if fmt == "json":
        return formats.read_json_cameras(inputs, distortion or "keep", unit)
    if fmt == "rig":
        return read_rig_json(inputs[0])
    raise ValueError(f"unknown format {fmt!r}; choose from {formats.FORMATS}")


def write_rig(rig: Rig, fmt: str, out: Path) -> list[Path]:
    if fmt == "rig":
        write_rig_json(rig, out)
        return [out]
    if fmt == "mvor":
        formats.write_mvor(rig, out)
        return [out]
    writer = {
        "opencv-yaml": formats.write_opencv_yaml,
        "4d-or": formats.write_4dor,
        "json": formats.write_json_cameras,
    }
    if fmt not in writer:
        raise ValueError(f"unknown format {fmt!r}; choose from {formats.FORMATS}")
    return writer[fmt](rig, out)


def convert(args: argparse.Namespace) -> int:
    if (args.src is None) == (args.dst is None):
        raise SystemExit("give exactly one of --from FORMAT (to rig.json) or --to FORMAT (from rig.json)")
    src, dst = (args.src, "rig") if args.src else ("rig", args.dst)
    rig = read_rig(src, args.inputs, args.distortion, args.unit)
    if args.names:
        if len(args.names) != len(rig):
            raise SystemExit(f"--names gives {len(args.names)} names for {len(rig)} cameras")
        rig.names = list(args.names)
    if args.ref == "first":
        rig = rig.to_first_camera()
        rig.report.append("reference frame: camera 0 (the first camera's extrinsics are the identity)")
    elif src == "mvor":
        rig = rig.to_room_frame()
        rig.report.append("reference frame: MVOR's room frame (firstCamToRoomRef)")
    else:
        rig.report.append(f"reference frame: the input's ({rig.frame})")
    written = write_rig(rig, dst, args.out)
    for line in rig.report:
        print(line)
    print(f"wrote {', '.join(str(p) for p in written)} ({len(rig)} cameras, {dst})")
    return 0


def check(args: argparse.Namespace) -> int:
    import cv2
    import torch

    from posenet.rig.check import (
        AGREE_MM,
        camera_agreement,
        depth_agreement,
        depth_checks,
        floor_of_frame,
        sanity_checks,
    )
    from posenet.rig.picture import draw_rig, up_vector

    rig = read_rig(args.format, [args.rig])
    results = sanity_checks(rig)
    for level, message in results:
        print(f"{level:4s} {message}")
    up = None if args.up is None else torch.tensor(args.up, dtype=torch.float64)
    depths = []
    for p in args.depth_frames or []:
        d = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if d is None or d.dtype != "uint16" or d.ndim != 2:
            raise ValueError(f"depth frame {p} is not a single-channel 16-bit image (uint16 mm)")
        depths.append(d)
    if depths and len(depths) != len(rig):
        raise ValueError(
            f"{len(depths)} depth frames for {len(rig)} cameras: give one per camera, in rig order"
        )
    for level, message in depth_checks(depths):
        print(f"{level:4s} {message}")
        results.append((level, message))
    floor, up_source = None, None
    if depths and up is None:
        drawn_rig, guess, _ = up_vector(rig)
        found = floor_of_frame(drawn_rig.cameras, depths, guess, stride=8)
        if found is None:
            print(
                "WARN floor: no large surface below the cameras in the depth frames; up estimated without it"
            )
        else:
            up, floor, share = found
            rig, up_source = drawn_rig, "floor fitted to the depth frames"
            heights = ", ".join(f"{(float(c.position @ up) - floor) / 1000:.2f}" for c in rig.cameras)
            print(
                f"OK   floor: {100 * share:.0f} % of the depth points lie within 40 mm of a plane; cameras {heights} m above it"
            )
    if not args.no_picture:
        picture = args.picture or args.rig.with_suffix(".png")
        drawn = draw_rig(rig, picture, up=up, title=args.title, floor_mm=floor, up_source=up_source)
        cover = ", ".join(f">={k} views {a:.1f} m2" for k, a in drawn["coverage"].items())
        print(f"picture: {picture} (up: {drawn['up_source']}; working plane coverage {cover})")
    failed = any(level == "FAIL" for level, _ in results)
    if depths:
        print(f"depth agreement (view i's points in view j; |diff| < {AGREE_MM:.0f} mm counts as agreeing):")
        pairs = depth_agreement(rig, depths, stride=args.stride)
        for r in pairs:
            i, j = r["pair"]
            print(f"  {i} -> {j}: overlap {100 * r['overlap']:5.1f} %, median |diff| {r['median_abs_mm']:6.1f} mm, "
                  f"median diff {r['median_mm']:+6.1f} mm, within {100 * r['within']:5.1f} %")  # fmt: skip
        per_camera = camera_agreement(pairs, len(rig))
        print(
            "  per camera, mean within over its pairs: "
            + ", ".join(f"{v}: {100 * a:.1f} %" for v, a in enumerate(per_camera))
        )
        mean = sum(r["within"] for r in pairs) / len(pairs)
        if mean < 0.6:  # most points disagree: would the transforms read the other way round fit?
            inverse = [dataclasses.replace(c, extrinsics=rigid_inverse(c.extrinsics)) for c in rig.cameras]
            flipped = depth_agreement(Rig(inverse, rig.names), depths, stride=args.stride)
            other = sum(r["within"] for r in flipped) / len(flipped)
            level = "WARN" if other > mean + 0.2 else "INFO"
            print(f"{level} only {100 * mean:.0f} % of the overlapping points agree; with the extrinsics inverted "
                  f"(T(ref->v) read as T(v->ref)) {100 * other:.0f} % would"
                  + (": the rig file probably holds the inverse transforms" if level == "WARN" else ""))  # fmt: skip
            failed = True
    return 1 if failed else 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m posenet.rig", description=__doc__.split("\n\n")[0],
                                     epilog=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("convert", help="convert a rig to rig.json (--from) or from rig.json (--to)")
    c.add_argument("inputs", type=Path, nargs="+", help="input file(s), or the folder holding them")
    c.add_argument("--from", dest="src", choices=formats.FORMATS, help="input format; output is rig.json")
    c.add_argument("--to", dest="dst", choices=formats.FORMATS, help="output format; input is rig.json")
    c.add_argument("--out", type=Path, required=True, help="rig.json, or the file/folder of the --to format")
    c.add_argument("--ref", choices=("first", "world"), default="first",
                   help="reference frame: the first camera's (default) or the input's world frame")  # fmt: skip
    c.add_argument(
        "--unit",
        choices=("mm", "cm", "m"),
        help="unit of the input's translations, when not the format's own",
    )
    c.add_argument("--distortion", choices=("keep", "drop"),
                   help="keep or drop lens distortion (default: drop for mvor and 4d-or, whose 3D labels ignore it)")  # fmt: skip
    c.add_argument("--names", nargs="+", help="camera names for the output (default: the input's)")
    k = sub.add_parser("check", help="sanity checks, a picture, and depth agreement between views")
    k.add_argument("rig", type=Path, help="rig.json (or another format with --format)")
    k.add_argument("--format", choices=formats.FORMATS, default="rig")
    k.add_argument(
        "--depth-frames", type=Path, nargs="+", help="one uint16 mm depth PNG per camera, same instant"
    )
    k.add_argument("--picture", type=Path, help="where to write the PNG (default: beside the rig, .png)")
    k.add_argument("--no-picture", action="store_true", help="checks only, no picture")
    k.add_argument(
        "--up", type=float, nargs=3, help="the floor's normal in the rig's frame (default: estimated)"
    )
    k.add_argument("--stride", type=int, default=4, help="use every n-th depth pixel (default: %(default)s)")
    k.add_argument("--title", help="the picture's title")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return convert(args) if args.command == "convert" else check(args)
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
