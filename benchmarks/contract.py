"""The OpenAPI contract against a real server: schemathesis with every check, with and without a token.

    python benchmarks/contract.py [--examples 250] [--seed N] [--no-results]

Starts ``uvicorn service.app:app`` with tiny random-init checkpoints (the tests' harness) twice, once without
``ORPOSE_TOKEN`` and once with it, and runs ``schemathesis run <url>/openapi.json -c all -n EXAMPLES`` against
each (with ``-H "Authorization: Bearer <token>"`` when set). ``--examples 250`` gives more than 2,000 cases per
token mode. Prints the cases, failures, errors and seconds per mode with the machine line, and appends a dated
section to benchmarks/RESULTS.md.

One thing the schema cannot say is passed to schemathesis in :data:`CONFIG`: a request that follows the schema
may still be refused with a 415 or a 422, because the rules that tie the parts together (a 16-bit depth PNG,
colour and depth of one size, the principal point inside the image, rigid extrinsics, exactly the parts of the
scene's views) are beyond JSON Schema. tests/service/test_contract.py runs a short version in CI.
"""

from __future__ import annotations

import argparse
import datetime
import re
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

TOKEN = "contract-token"
# positive_data_acceptance's defaults plus 415 and 422 for the two frame operations (the file says why); the
# same file makes a bare `schemathesis run` from the repository root agree.
CONFIG = (ROOT / "schemathesis.toml").read_text()
# schemathesis 4.32 raises this itself, now and then, when its negative mode mutates a form with file parts (a
# jsonschema-rs validator given its Binary wrapper): an error of the tool, no request is sent for it.
TOOL_ERROR = "Unsupported type: 'Binary'"


def schemathesis_command() -> str | None:
    """The ``schemathesis`` executable beside this Python, or on PATH; None when it is not installed."""
    beside = Path(sys.executable).parent / "schemathesis"
    return str(beside) if beside.exists() else shutil.which("schemathesis")


@contextmanager
def server(token: str | None, folder: Path):
    """A real server with tiny checkpoints (written under ``folder``), ``token`` as ORPOSE_TOKEN; yields its URL."""
    from service_harness import Server, tiny_checkpoints

    pose, det = tiny_checkpoints(folder)
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_DETECTOR_CHECKPOINT": str(det)}
    if token is not None:
        env["ORPOSE_TOKEN"] = token
    with Server(env) as url:
        yield url


def run(url: str, token: str | None, examples: int, seed: int | None = None, timeout_s: float = 1800) -> dict:
    """``schemathesis run URL/openapi.json -c all -n EXAMPLES`` with :data:`CONFIG`.

    Returns cases (generated), failures (unique), errors, tool_errors (of them, :data:`TOOL_ERROR`), seconds,
    the exit code and the output."""
    command = schemathesis_command()
    if command is None:
        raise RuntimeError("schemathesis is not installed")
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "schemathesis.toml"
        config.write_text(CONFIG)
        args = [command, "--config-file", str(config), "run", f"{url}/openapi.json", "-c", "all"]
        args += ["-n", str(examples), "--no-color", "--generation-database", "none"]
        args += ["--report-dir", str(Path(tmp) / "report")]
        if seed is not None:
            args += ["--seed", str(seed)]
        if token is not None:
            args += ["-H", f"Authorization: Bearer {token}"]
        t0 = time.perf_counter()
        done = subprocess.run(args, cwd=tmp, capture_output=True, text=True, timeout=timeout_s)
        seconds = time.perf_counter() - t0
    out = done.stdout + done.stderr
    return {
        "cases": _count(r"(\d+) generated", out),
        "failures": _count(r"found (\d+) unique failures?", out),
        "errors": _count(r"(\d+) errors?[, ].*in [\d.]+s", out),
        "tool_errors": len(re.findall(rf"^{re.escape(TOOL_ERROR)}$", out, re.M)),  # each error's title line
        "seconds": seconds,
        "returncode": done.returncode,
        "output": out,
    }


def _count(pattern: str, text: str) -> int:
    found = re.findall(pattern, text)
    return int(found[-1]) if found else 0


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=250, help="schemathesis -n (per operation and phase)")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--no-results", action="store_true", help="do not append to benchmarks/RESULTS.md")
    args = parser.parse_args(argv)

    import schemathesis

    from posenet.runtime.execution import machine_line

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for mode, token in (("no token", None), ("token", TOKEN)):
            with server(token, Path(tmp) / mode.replace(" ", "_")) as url:
                result = run(url, token, args.examples, args.seed)
            rows.append((mode, result))
            if result["failures"] or result["errors"] != result["tool_errors"]:
                print(result["output"][-20000:], file=sys.stderr)
    machine = machine_line()
    head = "| token mode | cases | failures | errors (schemathesis's own) | seconds |"
    lines = [head, "| --- | --- | --- | --- | --- |"]
    for mode, r in rows:
        lines.append(
            f"| {mode} | {r['cases']:,} | {r['failures']} | {r['errors']} ({r['tool_errors']}) | {r['seconds']:.0f} |"
        )
    table = "\n".join(lines)
    print(machine)
    print(f"schemathesis {schemathesis.__version__}, -c all -n {args.examples}")
    print(table)
    if args.no_results:
        return
    today = datetime.date.today().isoformat()
    section = (
        f"\n## contract.py: schemathesis against the OpenAPI contract ({today})\n"
        f"`python benchmarks/contract.py --examples {args.examples}`: schemathesis {schemathesis.__version__} "
        f"`run <url>/openapi.json -c all -n {args.examples}` against `uvicorn service.app:app` with tiny random "
        'checkpoints, without and with `ORPOSE_TOKEN` (`-H "Authorization: Bearer ..."`); the config passes '
        "415 and 422 as answers to schema-valid frames (the cross-part rules the schema cannot say); "
        f"{machine}.\n\n{table}\n\nErrors in brackets are schemathesis's own (its negative mode hands a "
        f"jsonschema-rs validator its Binary wrapper of a file part: {TOOL_ERROR}); no request is sent for them.\n"
    )
    with open(ROOT / "benchmarks" / "RESULTS.md", "a") as f:
        f.write(section)


if __name__ == "__main__":
    main()
