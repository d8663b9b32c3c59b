"""Does a change make the test suite slower? The suite at two commits, side by side, test by test.

    python benchmarks/ci_time.py --before 2f214a0                 # against HEAD
    python benchmarks/ci_time.py --before 2f214a0 --after a029d1f --json ci.json

Each commit is checked out into a git worktree beside this repository (``../.ci_time_SHA``, removed after, so
that ``../shared`` is where the tests expect it) and runs the README's test command, ``pytest -q``, with ``--durations=0``, in this
environment (``PYTHONPATH`` set to the worktree, so that every subprocess a test starts imports that commit's
code). The table gives each run's wall time and test count, then the tests present at both commits (matched by
test name and parameters: a test that moved to another file is still the same test) summed before and after, and
what the tests that exist only at one commit cost. A restructure that makes the same tests slower shows in the
common row; new features show in the "only after" row. The two runs are sequential: run it on an idle machine.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

from posenet.runtime.execution import machine_line

ROOT = Path(__file__).resolve().parents[1]
_DURATION = re.compile(r"\s*([\d.]+)s (?:call|setup|teardown)\s+(\S+)")


def durations_of(log: str) -> dict[str, float]:
    """Seconds per test (setup + call + teardown) from pytest's ``--durations=0`` report, keyed by the test's
    name and parameters without its file."""
    out: dict[str, float] = defaultdict(float)
    for line in log.splitlines():
        m = _DURATION.match(line)
        if m:
            out[m.group(2).split("::", 1)[-1]] += float(m.group(1))
    return dict(out)


def run_suite(commit: str, select: str | None = None) -> dict:
    """pytest at ``commit`` in a temporary worktree beside this repository: wall seconds, counts, durations."""
    sha = subprocess.run(["git", "rev-parse", "--short", commit], cwd=ROOT, check=True, capture_output=True,
                         text=True).stdout.strip()  # fmt: skip
    tree = ROOT.parent / f".ci_time_{sha}"  # beside the repository, so that the tests find ../shared
    subprocess.run(
        ["git", "worktree", "add", "-q", "--detach", "--force", str(tree), sha], cwd=ROOT, check=True
    )
    try:
        env = {**os.environ, "PYTHONPATH": str(tree), "HF_HUB_OFFLINE": "1"}
        t0 = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "--durations=0", "-p", "no:cacheprovider"]
            + (["-k", select] if select else []),
            cwd=tree, env=env, capture_output=True, text=True,
        )  # fmt: skip
        wall = time.perf_counter() - t0
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
    summary = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
    counts = {k: int(n) for n, k in re.findall(r"(\d+) (passed|failed|skipped|errors?)", summary)}
    return {"commit": sha, "wall_s": round(wall, 1), "returncode": done.returncode, "summary": summary,
            "counts": counts, "durations": durations_of(done.stdout)}  # fmt: skip


def compare(before: dict, after: dict) -> dict:
    a, b = before["durations"], after["durations"]
    common = set(a) & set(b)
    grew = sorted(common, key=lambda n: b[n] - a[n], reverse=True)
    return {
        "common_tests": len(common),
        "common_before_s": round(sum(a[n] for n in common), 1),
        "common_after_s": round(sum(b[n] for n in common), 1),
        "only_before": len(set(a) - common),
        "only_before_s": round(sum(a[n] for n in set(a) - common), 1),
        "only_after": len(set(b) - common),
        "only_after_s": round(sum(b[n] for n in set(b) - common), 1),
        "grew_most": [(n, round(a[n], 1), round(b[n], 1)) for n in grew[:5]],
        "slowest_only_after": sorted(((n, round(b[n], 1)) for n in set(b) - common), key=lambda x: -x[1])[:8],
    }


def format_table(before: dict, after: dict, cmp: dict) -> str:
    rows = [
        "| | before | after |",
        "| --- | --- | --- |",
        f"| commit | {before['commit']} | {after['commit']} |",
        f"| pytest wall (s) | {before['wall_s']} | {after['wall_s']} |",
        f"| result | {before['summary']} | {after['summary']} |",
        f"| the {cmp['common_tests']} tests at both commits (s) | {cmp['common_before_s']} | {cmp['common_after_s']} |",
        f"| tests at one commit only | {cmp['only_before']}: {cmp['only_before_s']} s | {cmp['only_after']}: "
        f"{cmp['only_after_s']} s |",
    ]
    lines = rows + ["", "common tests that grew most (s, before -> after):"]
    lines += [f"  {n}: {x} -> {y}" for n, x, y in cmp["grew_most"]]
    lines += ["slowest tests only after (s):"] + [f"  {n}: {t}" for n, t in cmp["slowest_only_after"]]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--before", required=True, help="the reference commit")
    parser.add_argument("--after", default="HEAD", help="the commit to compare (default: HEAD)")
    parser.add_argument("--json", type=Path, help="also write both runs and the comparison here")
    parser.add_argument(
        "--select", help="only the tests pytest -k selects (a quick check of the tool itself)"
    )
    args = parser.parse_args(argv)
    print(machine_line(), flush=True)
    before = run_suite(args.before, args.select)
    print(f"before ({before['commit']}): {before['summary']} in {before['wall_s']} s", flush=True)
    after = run_suite(args.after, args.select)
    print(f"after ({after['commit']}): {after['summary']} in {after['wall_s']} s", flush=True)
    cmp = compare(before, after)
    print(format_table(before, after, cmp))
    result = {"machine": machine_line(), "before": before, "after": after, "comparison": cmp}
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
