"""The shape every bad-input test of the CLI checks: exit status 2, one `wmdist: error:` line, no traceback."""
from __future__ import annotations

from wmdist.cli import main


def one_line_exit_2(capsys, argv: list[str]) -> tuple[str, str]:
    """Run the CLI in-process; return (the error line, what went to stdout)."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wmdist: error: "), captured.err
    assert "Traceback" not in captured.out + captured.err
    return lines[0], captured.out
