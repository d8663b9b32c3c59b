"""Who was tracked when: per ground-truth person, the track the service followed them with, frame by frame.

    python benchmarks/track_timeline.py --data data/seq_long --served off.jsonl on.jsonl --labels off on \\
        --out docs/img/track_timeline.png

Each ground-truth person of the sequence gets one row per served run (the JSON lines of ``python -m
service.client DATA --track``): a frame is coloured by the track whose smoothed joints were paired with the person
(optimal assignment on the mean joint distance, gated at 50 cm as ``pipeline.track_eval``), grey where the person
is in the frame and no track was, white where they are not in the frame, and lighter where the service answered
that person as one the detector was unsure of (``unsure``). A change of colour along a row is an id switch; grey
is a miss. The printout counts, per run, the frames covered
and those covered by unsure persons.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from tracking import sequences, served_lines, served_tracks  # noqa: E402

from pipeline.track_eval import gated_pairs
from posenet.data.mvor import load_annotations


def coverage(gt: dict, lines: dict, sequence: int) -> dict[int, list[tuple[str | int | None, bool]]]:
    """Per ground-truth person, per frame of ``sequence``: (the track paired with them, "missed" where they are
    annotated and no track is, None where they are not in the frame; answered as unsure)."""
    rows = sequences(gt)[sequence]
    people = sorted({int(i) for _, frame in rows for i in frame.gt_ids})
    out = {p: [(None, False)] * len(rows) for p in people}
    for f, (frame_id, frame) in enumerate(rows):
        for g in frame.gt_ids:
            out[int(g)][f] = ("missed", False)
        tracks, _ = served_tracks(lines, frame_id)
        unsure = {p["track_id"] for p in lines[frame_id]["response"]["persons"] if p.get("unsure")}
        for g, t in gated_pairs(frame.gt_joints, tracks):
            out[int(frame.gt_ids[g])][f] = (t, t in unsure)
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument(
        "--data", type=Path, required=True, help="a rendered sequence (posenet.synth --sequence)"
    )
    p.add_argument(
        "--served", type=Path, nargs="+", required=True, help="JSON lines of `service.client --track`"
    )
    p.add_argument("--labels", nargs="+", help="a name per --served file (default: the file names)")
    p.add_argument("--sequence", type=int, help="which sequence of the file (default: the first)")
    p.add_argument("--out", type=Path, required=True, help="the picture (PNG)")
    args = p.parse_args(argv)
    labels = args.labels or [s.stem for s in args.served]
    if len(labels) != len(args.served):
        p.error(f"{len(labels)} --labels for {len(args.served)} --served files")
    gt = load_annotations(args.data / "annotations.json")
    sequence = args.sequence if args.sequence is not None else min(sequences(gt))
    runs = []
    for path, label in zip(args.served, labels, strict=True):
        cover = coverage(gt, served_lines(path), sequence)
        covered = sum(isinstance(t, int) for row in cover.values() for t, _ in row)
        unsure = sum(u for row in cover.values() for _, u in row)
        total = sum(t is not None for row in cover.values() for t, _ in row)
        print(
            f"{label}: {covered} of {total} person-frames covered by a track, {unsure} of them by unsure persons"
        )
        runs.append((label, cover))
    people = sorted(runs[0][1])
    colours = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(10, 0.45 * len(people) * len(runs) + 1.2))
    y, ticks = 0, []
    for person in people:
        for label, cover in runs:
            for f, (track, unsure) in enumerate(cover[person]):
                if track == "missed":
                    ax.barh(y, 1, left=f, height=0.8, color="0.85", linewidth=0)
                elif track is not None:
                    ax.barh(y, 1, left=f, height=0.8, color=colours(track % 10), alpha=0.35 if unsure else 1.0,
                            linewidth=0)  # fmt: skip
            ticks.append((y, f"person {person}, {label}"))
            y += 1
        y += 0.5
    ax.set_yticks([t for t, _ in ticks], [s for _, s in ticks])
    ax.invert_yaxis()
    ax.set_xlabel(
        "frame (colour: track id; lighter: answered as unsure; grey: in the frame, no track; white: absent)"
    )
    ax.set_title(f"{args.data.name}: the track that followed each person")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
