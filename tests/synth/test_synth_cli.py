"""The renderer's command line: a newcomer without MVOR's annotation file is told where to get it."""

from __future__ import annotations

import pytest

from posenet.synth.__main__ import main


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (
            ["--scenes", "12", "--rig", "mvor", "--mvor-annotations", "/nonexistent/mvor.json"],
            "--mvor-annotations",
        ),
        (["--from-mvor", "/nonexistent/mvor.json"], "--from-mvor"),
    ],
)
def test_missing_mvor_file_says_where_to_get_it(tmp_path, argv, flag):
    with pytest.raises(SystemExit) as exit_:
        main(["--out", str(tmp_path / "out"), "--quiet", *argv])
    message = str(exit_.value)
    assert "/nonexistent/mvor.json" in message and "github.com/CAMMA-public/MVOR" in message
    assert flag in message and "--rig random" in message
    assert not (tmp_path / "out").exists()  # nothing was rendered or written
