"""Every subcommand checks its output paths before any work (physrelight.cli_common.check_outputs), and argument
errors are one line: exit 2, nothing written (issue 41, item 4; these failed on 4ce9156)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from physrelight import cli, cli_common
from ..cli_refusal import refused


@pytest.fixture()
def place(tmp_path: Path, monkeypatch) -> Path:
    """A folder with a regular file FILE and a folder DIR in it (the working directory)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "FILE").write_text("x")
    (tmp_path / "DIR").mkdir()
    return tmp_path


def test_01_output_folder_checks(place: Path) -> None:
    assert cli_common.check_output_folder("DIR") == Path("DIR")
    assert cli_common.check_output_folder("new/deeper/still") == Path("new/deeper/still")  # made later
    with pytest.raises(ValueError, match="'FILE' is a file, not a folder"):
        cli_common.check_output_folder("FILE")
    with pytest.raises(ValueError, match="cannot make output folder 'FILE/sub': 'FILE' is a file"):
        cli_common.check_output_folder("FILE/sub")
    with pytest.raises(ValueError, match="'/proc' does not take new files"):
        cli_common.check_output_folder("/proc/nope/rep")
    with pytest.raises(ValueError, match="empty path"):
        cli_common.check_output_folder("")
    assert sorted(os.listdir(place)) == ["DIR", "FILE"]  # the probes leave nothing


def test_02_output_file_checks(place: Path) -> None:
    assert cli_common.check_output_file("FILE") == Path("FILE")  # an existing file is overwritten: fine
    assert cli_common.check_output_file("new/o.json") == Path("new/o.json")
    with pytest.raises(ValueError, match="'DIR' is a folder, not a file"):
        cli_common.check_output_file("DIR")
    with pytest.raises(ValueError, match="'FILE' is a file, not a folder"):
        cli_common.check_output_file("FILE/o.json")
    with pytest.raises(ValueError, match="does not take new files"):
        cli_common.check_output_file("/proc/o.json")
    assert sorted(os.listdir(place)) == ["DIR", "FILE"]


def test_03_the_output_may_not_be_an_input(place: Path) -> None:
    os.symlink("FILE", "LINK")
    for out in ("FILE", "./FILE", "DIR/../FILE", "LINK", str(place / "FILE")):
        with pytest.raises(ValueError, match="is the input photo 'FILE'"):
            cli_common.check_not_input(out, {"input photo": "FILE", "--mask": None})
    cli_common.check_not_input("DIR/FILE", {"input photo": "FILE"})  # another file of the same name


@pytest.mark.parametrize("args, match", [
    (["demo", "-o", "FILE"], "output 'FILE' is a file, not a folder"),
    (["demo", "-o", "/proc/nope/demo"], "does not take new files"),
    (["train", "inverse", "--data", "d", "--out", "FILE"], "--out 'FILE' is a file"),
    (["train", "shadow", "--data", "d", "--out", "FILE", "--inverse", "x"], "--out 'FILE' is a file"),
    (["train", "renderer", "--data", "d", "--out", "FILE/run"], "'FILE' is a file"),
    (["train", "sky", "--data", "d", "--out", "run", "--json", "DIR"], "--json 'DIR' is a folder"),
    (["train", "segmentation", "--data", "d", "--out", "run", "--export", "DIR"], "--export 'DIR' is a folder"),
    (["train", "evaluate", "--data", "d", "--json", "DIR"], "--json 'DIR' is a folder"),
    (["train", "evaluate-relight", "--data", "d", "--json", "/proc/x.json"], "does not take new files"),
    (["train", "export", "--inverse", "r", "--dest", "FILE"], "--dest 'FILE' is a file"),
    (["train", "export-renderer", "--run", "r", "--dest", "DIR"], "--dest 'DIR' is a folder"),
])
def test_04_every_subcommand_checks_its_outputs_before_any_work(place: Path, capsys, args: list[str],
                                                                match: str) -> None:
    """The inputs named here do not exist: the output check comes first, so no stage even looks for them."""
    if args[0] == "demo":
        args = [*args, "--physics-only"]
    refused(capsys, args, match)
    assert sorted(os.listdir(place)) == ["DIR", "FILE"]


def test_05_every_subcommand_declares_its_outputs() -> None:
    """Each (sub)parser that takes an output path names it in output_files/output_folders."""
    import argparse

    outputs = {"output", "out", "dest", "json", "export", "layers"}
    for name in cli.SUBCOMMANDS:
        todo = [cli.build_parser(name)]
        while todo:
            p = todo.pop()
            subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
            for s in subs:
                todo.extend(s.choices.values() if p.prog != "physrelight" else [s.choices[name]])
            if subs:
                continue
            dests = {a.dest for a in p._actions} & outputs
            declared = set(p.get_default("output_files") or ()) | set(p.get_default("output_folders") or ())
            assert dests <= declared, (p.prog, dests - declared)


def test_06_an_argument_error_is_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["demo", "--size", "0"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1
    assert err.startswith("physrelight demo: error: argument --size: expected a positive integer, got 0")
