"""The shape of every command-line refusal, shared by the ``test_*cli*`` modules: exit status 2, no traceback,
one line on stderr, ``physrelight: error: ...`` naming the problem."""

from __future__ import annotations

from physrelight.cli import main


def refused(capsys, args: list[str], match: str, last_line: bool = False) -> str:
    """Run ``physrelight ARGS``; assert it was refused with ``match`` in its line, and return that line
    (``last_line``: the refusal is the last line of stderr, after a progress bar, rather than its only line)."""
    rc = main(args)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err, err
    line = err.rstrip("\n").split("\n")[-1] if last_line else err
    if not last_line:
        assert err.count("\n") == 1, err
    assert line.startswith("physrelight: error:") and match in line, err
    return line
