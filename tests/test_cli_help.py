"""Every help page of the command line: ``boucwen --help`` and ``boucwen CMD --help``
for every subcommand of the parser, formatted without error (a ``%`` in a help string
goes through argparse's %-formatting) and saying what each option's default is."""

import argparse
import re
import subprocess
import sys

import pytest

from boucwen.cli import build_parser, main


def _subcommands():
    """The parser's subcommands by name, read from the parser itself."""
    parser = build_parser()
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert len(actions) == 1
    return dict(actions[0].choices)


SUBCOMMANDS = sorted(_subcommands())


def test_the_walk_finds_every_subcommand():
    # The shell's documented commands are all registered (a new one is walked by the tests below).
    assert {"fit", "diagnose", "identify", "invert", "simulate", "reproduce", "batch", "track"} <= set(SUBCOMMANDS)


@pytest.mark.parametrize("command", [None, *SUBCOMMANDS])
def test_help_exits_zero_and_shows_usage(capsys, command):
    argv = ["--help"] if command is None else [command, "--help"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("usage: boucwen") and captured.err == ""
    if command is None:
        assert all(name in captured.out for name in SUBCOMMANDS)
    else:
        assert f"boucwen {command}" in captured.out


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_option_has_help_that_formats(command):
    parser = _subcommands()[command]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        names = "/".join(action.option_strings) or action.dest
        assert action.help, f"boucwen {command} {names}: no help text"
        # What argparse does to a help string: %-formatting with the action's fields.
        params = {**vars(action), "prog": parser.prog}
        text = action.help % params
        assert "%(" not in text, f"boucwen {command} {names}: unexpanded {text!r}"


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_defaults_said_in_the_help_are_the_defaults(command):
    # "(default 4)" in a help string must be the option's default, not an older one.
    parser = _subcommands()[command]
    checked = 0
    for action in parser._actions:
        said = re.search(r"\(default ([^\s;,)]+)", action.help or "")
        if said is None or action.default is None or isinstance(action.default, bool):
            continue
        value = said.group(1)
        if isinstance(action.default, (int, float)):
            assert float(value) == pytest.approx(float(action.default)), (command, action.option_strings, value)
        else:
            assert value == str(action.default), (command, action.option_strings, value)
        checked += 1
    if command in ("fit", "identify", "reproduce", "track"):
        assert checked > 0


def test_help_in_a_real_process():
    # The entry point as a shell runs it: no traceback, exit 0, for every page.
    for argv in (["--help"], *([name, "--help"] for name in SUBCOMMANDS)):
        proc = subprocess.run([sys.executable, "-m", "boucwen.cli", *argv], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0 and proc.stderr == "", (argv, proc.stderr)
        assert proc.stdout.startswith("usage: boucwen"), argv
