"""posenet.cli: a config dataclass's fields as command-line options, and the tools that declare theirs with it."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

import pytest

from posenet.cli import add_config_options, config_options


@dataclass
class _Config:
    name: str
    lr: float = 1e-3
    steps: int | None = None
    days: list[int] = field(default_factory=lambda: [1, 2])
    flip: bool = True
    rotate_deg: float = 15.0


HELPS = {"lr": "rate", "steps": "steps", "days": "days", "flip": "flip", "rotate_deg": "degrees"}


def _parser(config) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    add_config_options(p, config, HELPS, flags={"rotate_deg": "--rotate"})
    return p


def test_options_take_their_type_arity_and_default_from_the_dataclass():
    p = _parser(_Config("x"))
    args = p.parse_args([])
    assert (args.lr, args.steps, args.days, args.flip, args.rotate_deg) == (1e-3, None, [1, 2], True, 15.0)
    args = p.parse_args(["--lr", "0.5", "--steps", "7", "--days", "3", "4", "--no-flip", "--rotate", "5"])
    assert (args.lr, args.steps, args.days, args.flip, args.rotate_deg) == (0.5, 7, [3, 4], False, 5.0)
    assert isinstance(args.steps, int) and isinstance(args.days[0], int)
    assert _Config(name="x", **config_options(args, _Config)) == _Config("x", 0.5, 7, [3, 4], False, 5.0)
    with pytest.raises(SystemExit):
        p.parse_args(["--steps", "1.5"])  # an int field refuses a float
    assert "(default: 0.001)" in p.format_help()


def test_from_the_class_every_option_defaults_to_none_so_a_preset_fills_in():
    args = _parser(_Config).parse_args(["--lr", "2"])
    assert config_options(args, _Config) == {"lr": 2.0}  # only what was given


def test_a_field_the_config_does_not_have_is_refused():
    with pytest.raises(KeyError, match="no field 'nope'"):
        add_config_options(argparse.ArgumentParser(), _Config, {"nope": "?"})


@pytest.mark.parametrize(
    "module, argv, field_name, value",
    [
        ("posenet.training.train", ["--rotate", "5", "--view-loss", "0.5"], "rotate_deg", 5.0),
        ("posenet.training.adapt", ["--pseudo", "0.25", "--min-views", "3"], "min_views", 3),
        ("detector.train", ["--lr", "2e-5", "--no-cache"], "cache", False),
        ("detector.adapt", ["--unsettled-floor", "0.2", "--frames-per-round", "8"], "unsettled_floor", 0.2),
    ],
)
def test_the_training_tools_declare_their_options_from_their_configs(module, argv, field_name, value):
    import importlib

    parser = importlib.import_module(module).build_parser()
    args = parser.parse_args(["--data", "D", "--out", "O", *argv])
    assert getattr(args, field_name) == value
