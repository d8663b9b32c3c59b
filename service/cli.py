"""``orpose``: one command for everything the package does; each subcommand is the ``python -m`` tool it names.

    orpose serve --port 8000                 # uvicorn service.app:app
    orpose render --out data/seq --sequence  # python -m posenet.synth
    orpose train --help                      # python -m posenet.training.train

Every subcommand takes the arguments of its module (``orpose SUBCOMMAND --help``); the ``python -m`` forms stay.
Modules are imported only when their subcommand runs, so ``orpose --help`` is instant.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# subcommand: (module whose main(argv) runs it, one line of help); grouped as the help lists them
COMMANDS: dict[str, tuple[str, str]] = {
    "serve": ("uvicorn", "run the HTTP service (uvicorn service.app:app; uvicorn's options, e.g. --port)"),
    "client": ("service.client", "send a recorded dataset through a running service, resumably"),
    "export": ("service.export", "build the inference runtime's graphs (and the int8 ones) ahead of first start"),
    "render": ("posenet.synth.__main__", "render synthetic multi-view RGB-D OR scenes in MVOR's layout"),
    "rig": ("posenet.rig.__main__", "convert and check camera rigs (rig.json, MVOR, OpenCV YAML, 4D-OR)"),
    "or4d": ("posenet.data.or4d", "convert a 4D-OR recording to MVOR's layout"),
    "train": ("posenet.training.train", "train the pose network"),
    "adapt": ("posenet.training.adapt", "adapt the pose network to an OR's recordings without 3D poses"),
    "predict": ("posenet.evaluation.predict", "3D poses of a dataset's frames (reference or detector boxes)"),
    "evaluate": ("posenet.evaluation.evaluate", "MPJPE per joint type and per support, as the paper reports it"),
    "calibrate": ("posenet.evaluation.calibrate", "fit the joints' confidence to their error"),
    "visualize": ("posenet.viz.visualize", "draw a frame's heatmaps, lifted points and skeletons"),
    "animate": ("posenet.viz.animate", "animate predicted skeletons over a sequence"),
    "detector-train": ("detector.train", "train the person detector"),
    "detector-predict": ("detector.predict", "person boxes of a dataset's views"),
    "detector-evaluate": ("detector.evaluate", "COCO AP of predicted boxes"),
    "detector-adapt": ("detector.adapt", "adapt the person detector to an OR's unlabelled recordings"),
    "detector-export": ("detector.export", "ship a detector run: NMS, score threshold, int8 weights"),
    "group": ("pipeline.group", "detect and group boxes across views (the input of adapt --boxes detector)"),
    "associate": ("pipeline.association", "evaluate the cross-view association of boxes"),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="orpose",
        description="Multi-view RGB-D 3D human pose for operating rooms. Run `orpose SUBCOMMAND --help` for a "
        "subcommand's options.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="subcommands:\n" + "\n".join(f"  {name:<18} {text}" for name, (_, text) in COMMANDS.items()),
    )
    p.add_argument("command", choices=list(COMMANDS), metavar="SUBCOMMAND", help="what to run (listed below)")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        build_parser().print_help()
        return 0 if argv else 2
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        build_parser().parse_args([command])  # exits with argparse's message naming the choices
    module = COMMANDS[command][0]
    sys.argv = [f"orpose {command}", *rest]  # what the subcommand's --help and errors print
    if command == "serve":
        import uvicorn

        return uvicorn.main.main(args=["service.app:app", *rest], prog_name="orpose serve", standalone_mode=True)
    result = importlib.import_module(module).main(rest)
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    raise SystemExit(main())
