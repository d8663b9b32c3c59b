"""Every tool command the README shows exists and takes the options it is shown with.

Each ``.venv/bin/python -m MODULE ...``, ``.venv/bin/python benchmarks/X.py ...`` and ``.venv/bin/orpose SUB ...``
line of the README's ``bash`` blocks runs in one child process up to its argument parsing: ``parse_args`` is
wrapped to stop the program right after it parsed, so nothing is rendered or trained. A renamed module, a
dropped or misspelt option, or an option's missing value fails here with argparse's own message.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Runs in the child: each command up to its parse, its outcome as one JSON line.
_CHILD = r"""
import argparse, contextlib, io, json, runpy, sys

class Parsed(BaseException):
    pass

original = argparse.ArgumentParser.parse_args
def parse_args(self, args=None, namespace=None):
    original(self, args, namespace)
    raise Parsed
argparse.ArgumentParser.parse_args = parse_args

for line in sys.stdin:
    kind, target, argv = json.loads(line)
    err = io.StringIO()
    outcome = "ran past its parsing"
    sys.argv = [target, *argv]
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            if kind == "module":
                runpy.run_module(target, run_name="__main__", alter_sys=False)
            else:
                sys.path.insert(0, target.rsplit("/", 1)[0])  # as `python SCRIPT` would
                try:
                    runpy.run_path(target, run_name="__main__")
                finally:
                    sys.path.pop(0)
    except Parsed:
        outcome = "parsed"
    except SystemExit as e:  # --help exits 0 once it printed
        outcome = "parsed" if e.code in (0, None) else None
        outcome = outcome or f"exit {e.code}: {err.getvalue().strip()[-400:]}"
    except Exception as e:
        outcome = f"{type(e).__name__}: {e}"
    print(json.dumps(outcome), flush=True)
"""


def readme_commands() -> list[tuple[str, str, list[str]]]:
    """(kind, module or script, argv) of the README's tool commands, continuation lines joined."""
    text = (REPO / "README.md").read_text()
    found = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        env = dict(re.findall(r"^(\w+)=(\S+)$", block, re.M))
        for line in block.replace("\\\n", " ").splitlines():
            if line.lstrip().startswith("#"):
                continue
            for command in re.split(r"&&|;", line.split(" #")[0]):
                words = shlex.split(
                    re.sub(r"\$(\w+)", lambda m, env=env: env.get(m.group(1), m.group(0)), command)
                )
                if words[:2] == [".venv/bin/python", "-m"] and len(words) > 2:
                    found.append(("module", words[2], words[3:]))
                elif words[:1] == [".venv/bin/python"] and len(words) > 1 and words[1].endswith(".py"):
                    found.append(("script", str(REPO / words[1]), words[2:]))
                elif words[:1] == [".venv/bin/orpose"] and len(words) > 1 and words[1] != "serve":
                    found.append(("module", "service.cli", words[1:]))
    return found


def test_the_readme_shows_tool_commands():
    kinds = {(kind, target) for kind, target, _ in readme_commands()}
    assert len(kinds) >= 10
    assert ("module", "service.cli") in kinds and any(k == "script" for k, _ in kinds)


def test_every_readme_command_parses_as_written():
    commands = readme_commands()
    stdin = "".join(json.dumps(c) + "\n" for c in commands)
    run = subprocess.run(
        [sys.executable, "-c", _CHILD], input=stdin, capture_output=True, text=True, cwd=REPO, timeout=600
    )
    outcomes = [json.loads(line) for line in run.stdout.splitlines() if line.startswith('"')]
    assert len(outcomes) == len(commands), run.stderr[-2000:]
    failed = [
        f"{' '.join([t, *a])}: {o}" for (_, t, a), o in zip(commands, outcomes, strict=True) if o != "parsed"
    ]
    assert not failed, "\n".join(failed)
