"""The options every command-line tool shares, declared once: a dataset, its annotations, days and CPU threads;
and a config dataclass's fields as options (:func:`add_config_options`), so a tool names a field and its help,
never its type, arity or default again.

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
import dataclasses
import sys
import types
import typing
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


def _option_type(hint) -> tuple[type, bool]:
    """The scalar type of a config field's annotation and whether it is a list (``X``, ``X | None``,
    ``list[X]``, ``list[X] | None``)."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        hint = next(a for a in typing.get_args(hint) if a is not type(None))
    if typing.get_origin(hint) is list:
        return typing.get_args(hint)[0], True
    return hint, False


def add_config_options(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    config,
    helps: dict[str, str],
    flags: dict[str, str] | None = None,
) -> None:
    """One option per entry of ``helps`` (field name -> help), declared from the dataclass ``config``.

    The flag is the field's name with dashes (``flags`` may rename it: ``{"rotate_deg": "--rotate"}``) and its
    destination the field's name; its type and arity come from the field's annotation (``int``, ``float``,
    ``str``, ``X | None``, ``list[X]``: ``nargs="+"``; ``bool``: ``--x`` / ``--no-x``). With ``config`` a class
    the options default to None (the tool fills what is not given, e.g. from a preset); with an instance its
    values are the defaults, and the help shows them.
    """
    cls = config if isinstance(config, type) else type(config)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    scope = vars(sys.modules[cls.__module__])
    for name, help in helps.items():
        if name not in fields:
            raise KeyError(f"{cls.__name__} has no field {name!r}")
        hint = fields[name].type  # a string under `from __future__ import annotations`
        kind, many = _option_type(eval(hint, scope) if isinstance(hint, str) else hint)  # noqa: S307
        default = None if isinstance(config, type) else getattr(config, name)
        if default is not None:
            help = f"{help} (default: %(default)s)"
        flag = (flags or {}).get(name, "--" + name.replace("_", "-"))
        if kind is bool:
            p.add_argument(flag, dest=name, action=argparse.BooleanOptionalAction, default=default, help=help)
            continue
        metavar = flag.lstrip("-").replace("-", "_").upper()
        nargs = "+" if many else None
        p.add_argument(flag, dest=name, type=kind, nargs=nargs, default=default, metavar=metavar, help=help)


def config_options(args: argparse.Namespace, config: type) -> dict:
    """The fields of the dataclass ``config`` given on the command line (those of ``args`` that are not None)."""
    return {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(config)
        if getattr(args, f.name, None) is not None
    }
