"""``orpose``: the console entry point lists every subcommand, and each one runs its module's own parser."""

from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from service.cli import COMMANDS, main


def orpose() -> list[str]:
    exe = shutil.which("orpose") or shutil.which("orpose", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "service.cli"]


def test_help_lists_every_subcommand():
    r = subprocess.run([*orpose(), "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    for name in COMMANDS:
        assert f"  {name} " in r.stdout


@pytest.mark.parametrize("name", [n for n in COMMANDS if n != "serve"])
def test_every_subcommand_names_a_module_with_a_main(name):
    assert callable(importlib.import_module(COMMANDS[name][0]).main)


def test_a_subcommand_runs_its_modules_parser(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["render", "--help"])
    assert exit_.value.code == 0
    assert "--from-mvor" in capsys.readouterr().out


def test_an_unknown_subcommand_names_the_choices(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["trian"])
    assert exit_.value.code == 2
    assert "invalid choice: 'trian'" in capsys.readouterr().err


def test_serve_passes_uvicorns_options():
    r = subprocess.run([*orpose(), "serve", "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "--port" in r.stdout, r.stderr
