"""One vocabulary across commands: every command's help shows each option's metavar and
default, the same thing has the same option name (and metavar, and wording) everywhere, and
every command that validates takes ``--fail-on``. ``wrinklepipe/commands/_options.py`` declares
the shared options; a failure here names the command, the option and what to change."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys

import pytest

from wrinklepipe.cli import build_parser
from wrinklepipe.commands._options import HelpFormatter
from wrinklepipe.validate.catalogue import SEVERITIES

#: Commands whose run validates an asset: each must take --fail-on.
VALIDATING = {"demo", "convert", "validate-asset", "batch", "pack-masks"}

#: The shared options: option strings -> (metavar, what its help starts with).
SHARED = {
    "--output": (("-o", "--output"), "OUT"),
    "--report": (("--report",), "FILE"),
    "--jobs": (("-j", "--jobs"), "N"),
    "--allow-root": (("--allow-root",), "DIR"),
    "--fail-on": (("--fail-on",), "SEVERITY"),
}


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


COMMANDS = _commands()


def _options(p: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in p._actions if a.help != argparse.SUPPRESS and a.dest != "help"]


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_option_has_help_metavar_and_default(name):
    p = COMMANDS[name]
    assert isinstance(p._get_formatter(), HelpFormatter), (
        f"{name}: build_parser gives every command the shared HelpFormatter"
    )
    problems = []
    for a in _options(p):
        label = "/".join(a.option_strings) or a.dest
        text = p._get_formatter()._expand_help(a) if a.help else ""
        if not text.strip():
            problems.append(f"{label}: no help text")
        if a.nargs == 0:
            continue  # a flag: nothing to name, no default to show
        metavar = a.metavar
        if a.option_strings and metavar is None and a.choices is None:
            problems.append(f"{label}: no metavar (argparse would show {a.dest.upper()!r})")
        if isinstance(metavar, str) and (metavar != metavar.upper() or "_" in metavar):
            problems.append(f"{label}: metavar {metavar!r} is not one short UPPERCASE word")
        if a.option_strings and not (
            a.default is None or a.default == [] or a.default is argparse.SUPPRESS
        ):
            shown = p._get_formatter()._get_help_string(a)
            if "default" not in shown:
                problems.append(f"{label}: default {a.default!r} not shown in its help")
            elif "(default: %(default)s)" in shown and re.search(
                rf"\({re.escape(str(a.default))}[);,]", a.help
            ):
                problems.append(f"{label}: default shown twice (drop the '({a.default})')")
    assert not problems, f"wrinklepipe {name}:\n  " + "\n  ".join(problems)


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_shared_options_are_spelled_alike(name):
    problems = []
    for a in _options(COMMANDS[name]):
        for key, (strings, metavar) in SHARED.items():
            if key in a.option_strings:
                if tuple(a.option_strings) != strings:
                    problems.append(f"{key}: written {a.option_strings}, the vocabulary: {strings}")
                if a.metavar != metavar:
                    problems.append(f"{key}: metavar {a.metavar!r}, the vocabulary: {metavar!r}")
        if "--fail-on" in a.option_strings:
            assert tuple(a.choices) == SEVERITIES
        if "--json" in a.option_strings:
            assert "as JSON on stdout" in a.help, (
                f"{name} --json: say 'print ... as JSON on stdout'"
            )
        if "--force" in a.option_strings:
            assert a.help.startswith("replace "), f"{name} --force: say what it replaces"
    # the same thing under another name
    strings = {s for a in _options(COMMANDS[name]) for s in a.option_strings}
    for other, canonical in (("--summary", "--report"), ("--out", "--output")):
        if other in strings:
            problems.append(f"{other}: use {canonical} (keep {other} as a DeprecatedAlias)")
    assert not problems, f"wrinklepipe {name}:\n  " + "\n  ".join(problems)


def test_commands_that_validate_take_fail_on():
    missing = [
        n
        for n in VALIDATING
        if not any("--fail-on" in a.option_strings for a in _options(COMMANDS[n]))
    ]
    assert not missing


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_examples_use_known_options(name):
    """Every ``wrinklepipe NAME ...`` example in a help text parses (options exist, values are
    valid), so the help never shows an option the command does not take."""
    p = COMMANDS[name]
    text = re.sub(r"\\\n\s*", " ", p.description or "")  # join continued lines
    examples = [
        line.strip().split("  #")[0].strip()
        for line in text.splitlines()
        if re.match(rf"\s+wrinklepipe {re.escape(name)}\b", line)
    ]
    for example in examples:
        argv = example.split()[1:]  # the command's name first, as build_parser expects
        argv = [a.strip("'\"") for a in argv]
        try:
            build_parser(name).parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"`{example}` does not parse (exit {exc.code})")


def test_severities_are_validations():
    from wrinklepipe.commands import _options

    assert _options.SEVERITIES == SEVERITIES


def test_deprecated_alias_still_works_and_says_so(capsys):
    args = build_parser("batch").parse_args(["batch", "x.toml", "--summary", "s.json"])
    assert args.report == "s.json"
    assert "--summary is deprecated; use --report" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "usage", "hint"),
    [
        (["conver", "m.toml"], "wrinklepipe: error", "(did you mean 'convert'?)"),
        (["validate-assets", "x"], "wrinklepipe: error", "(did you mean 'validate-asset'?)"),
        (
            ["convert", "m.toml", "-o", "o", "--fial-on", "warning"],
            "wrinklepipe convert: error",
            "--fial-on (did you mean '--fail-on'?)",
        ),
        (
            ["inspect", "a.glb", "--jsn"],
            "wrinklepipe inspect: error",
            "unrecognized argument: --jsn (did you mean '--json'?)",
        ),
        (
            ["validate-asset", "x", "--fail-on", "warnig"],
            "wrinklepipe validate-asset: error",
            "invalid choice: 'warnig' (did you mean 'warning'?); "
            "choose from 'error', 'warning', 'info'",
        ),
        (
            ["export", "x", "--engine=Unreal", "-o", "o"],
            "wrinklepipe export: error",
            "(did you mean 'unreal'?)",
        ),
    ],
)
def test_a_mistyped_command_option_or_value_gets_a_did_you_mean(argv, usage, hint, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert usage in err and hint in err, err


def test_no_did_you_mean_when_nothing_is_close(capsys):
    for argv in (["frobnicate"], ["inspect", "a.glb", "--zzz"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(argv)
        err = capsys.readouterr().err
        assert "unrecognized argument: --zzz" in err or "invalid choice: 'frobnicate'" in err
        assert "did you mean" not in err, err


def test_the_console_script_exits_2_with_the_hint():
    proc = subprocess.run(
        [sys.executable, "-m", "wrinklepipe", "conver", "m.toml"], capture_output=True, text=True
    )
    assert proc.returncode == 2
    assert "did you mean 'convert'?" in proc.stderr and not proc.stdout
