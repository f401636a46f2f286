"""One progress style and one ``--quiet`` on every command: silent under --quiet, bars and status lines without."""

from __future__ import annotations

import argparse
import sys

import pytest

from gfimu.cli import COMMANDS, build_parser, main


def _parsers(parser, path=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield path + (name,), child
                yield from _parsers(child, path + (name,))


def test_every_command_takes_quiet_with_its_default_in_the_help():
    parser = build_parser("")
    seen = set()
    for path, child in _parsers(parser):
        seen.add(path[0])
        action = child._option_string_actions.get("--quiet")
        assert action is not None, path
        assert "default" in action.help, path
        no_progress = child._option_string_actions.get("--no-progress")
        if no_progress is not None:
            assert "default" in no_progress.help, path
    assert seen == set(COMMANDS)
    for command in ("estimate", "simulate", "compare", "calibrate", "plot", "batch", "demo"):
        assert "--no-progress" in dict(_parsers(parser))[(command,)]._option_string_actions, command


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    work = tmp_path_factory.mktemp("quiet")
    assert main(["simulate", "reversal", "--out", str(work / "log"), "--duration-s", "0.6", "--quiet"]) == 0
    return work


def test_quiet_commands_write_nothing_on_stderr(work, capsys, monkeypatch):
    capsys.readouterr()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)  # bars would show on a terminal
    runs = [
        ["simulate", "reversal", "--out", str(work / "log2"), "--duration-s", "0.4", "--quiet"],
        ["estimate", str(work / "log"), "--method", "ml", "--out", str(work / "ml.csv"), "-q"],
        ["--quiet", "estimate", str(work / "log"), "--method", "smoother", "--out", str(work / "sm.csv")],
        ["evaluate", str(work / "log"), str(work / "ml.csv"), "--out", str(work / "ev.md"), "--quiet"],
        ["compare", str(work / "log"), "--methods", "inversion,ml", "--out", str(work / "cmp.md"), "--quiet"],
    ]
    for argv in runs:
        assert main(argv) == 0, argv
        captured = capsys.readouterr()
        assert captured.err == "", (argv, captured.err)
        assert captured.out == "", (argv, captured.out)
    assert (work / "sm.csv").stat().st_size > 0 and (work / "cmp.md").read_text().count("| ml") >= 1


def test_without_quiet_status_lines_and_on_a_terminal_progress_bars(work, capsys, monkeypatch):
    capsys.readouterr()
    # not a terminal: no bars, the status lines stay
    assert main(["estimate", str(work / "log"), "--method", "smoother", "--out", str(work / "s1.csv")]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("smoother: readings consistent with a rigid body")  # the model check
    assert "it/s" not in captured.err and "\r" not in captured.err
    assert f"-> {work / 's1.csv'}" in captured.out
    # a terminal: tqdm's bar of the method on standard error
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert main(["estimate", str(work / "log"), "--method", "ml", "--out", str(work / "s2.csv")]) == 0
    captured = capsys.readouterr()
    assert "ml:" in captured.err and "%|" in captured.err
    # --no-progress: the bar goes, the status line stays
    assert main(["estimate", str(work / "log"), "--method", "ml", "--out", str(work / "s3.csv"),
                 "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "%|" not in captured.err and "-> " in captured.out


def test_step_bars_name_the_current_step_and_are_silent_when_disabled(capsys):
    from gfimu.progress import steps

    with steps("calibrate", ["read", "fit", "write"], enable=True) as bar:
        for name in ("read", "fit", "write"):
            bar.step(name)
    err = capsys.readouterr().err
    assert "calibrate: 0/3, read" in err and "calibrate: 1/3, fit" in err and "calibrate: 2/3, write" in err
    with steps("calibrate", ["read"], enable=False) as bar:
        bar.step("read")
    assert capsys.readouterr().err == ""
