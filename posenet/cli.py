"""The options every command-line tool shares, declared once: a dataset, its annotations, days and CPU threads.

    p = argparse.ArgumentParser(...)
    add_data(p)                      # --data DIR (required)
    add_annotations(p)               # --annotations A.json (default: DATA/annotations.json)
    add_days(p)                      # --days D [D ...]
    add_threads(p)                   # --threads N
    args = p.parse_args(argv)
    set_threads(args.threads)
    annotations = annotations_path(args)

Each helper takes the few things a tool may differ in (required, default, help); the flag's name, type and
arity are the same everywhere.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DATA_HELP = "dataset root in MVOR's layout (annotations.json, dayD/camC/{color,depth}/NNNNNN.png)"


def add_data(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    required: bool = True,
    help: str = DATA_HELP,
    **kwargs,
) -> argparse.Action:
    """``--data DIR``: an MVOR-format dataset (a string path)."""
    return p.add_argument("--data", required=required, help=help, **kwargs)


def add_annotations(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    required: bool = False,
    help: str = "MVOR-format annotation json (default: DATA/annotations.json)",
    **kwargs,
) -> argparse.Action:
    """``--annotations A.json``: the dataset's annotation file; :func:`annotations_path` fills in the default."""
    return p.add_argument("--annotations", required=required, help=help, **kwargs)


def annotations_path(args: argparse.Namespace) -> str | None:
    """``--annotations``, else ``DATA/annotations.json`` when ``--data`` is given, else None."""
    if getattr(args, "annotations", None):
        return args.annotations
    data = getattr(args, "data", None)
    return str(Path(data) / "annotations.json") if data else None


def add_days(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    help: str = "only these recording days (default: all)",
    default: list[int] | None = None,
    nargs: str = "+",
) -> argparse.Action:
    """``--days D [D ...]``: recording days, the cross-validation unit."""
    return p.add_argument("--days", type=int, nargs=nargs, default=default, metavar="D", help=help)


def add_threads(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    default: int | None = None,
    help: str = "torch's (and the inference runtimes') CPU threads (default: torch's choice)",
) -> argparse.Action:
    """``--threads N``: CPU threads; :func:`set_threads` applies it."""
    return p.add_argument("--threads", type=int, default=default, metavar="N", help=help)


def set_threads(threads: int | None) -> None:
    """Give torch ``threads`` intra-op threads (None or 0: leave torch's choice)."""
    if threads:
        import torch

        torch.set_num_threads(threads)
