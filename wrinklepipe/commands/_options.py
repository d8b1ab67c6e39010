"""The options several commands share, declared once: the same name, metavar, help and default
wherever they appear (``tests/test_cli_help.py`` checks every command against this vocabulary).
Not a command (the leading underscore keeps it out of the command list)."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Sequence
from typing import Any

from wrinklepipe.console import problem
from wrinklepipe.names import did_you_mean

#: Validation's severities, worst first (``wrinklepipe.validate.catalogue.SEVERITIES``; not
#: imported from there, which would load the whole validator for every command's ``--help``;
#: ``tests/test_cli_help.py`` checks the two agree).
SEVERITIES = ("error", "warning", "info")

#: The lowest severity that fails a run, unless --fail-on says otherwise.
DEFAULT_FAIL_ON = "error"


def finite_float(text: str) -> float:
    """A number option's value (``type=finite_float``): ``nan`` and ``inf``, which ``float``
    accepts, are refused as argparse refuses any other value that is not a number."""
    value = float(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number")
    return value


finite_float.__name__ = "number"  # argparse names the type so: "invalid number value: 'x'"


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """The description as written (its examples and tables keep their lines), and every
    option's default shown as ``(default: X)`` unless its help already says what it is."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if "default" in text or default is None or default is False or default == []:
            return text
        if default is argparse.SUPPRESS:
            return text
        if action.option_strings and action.nargs != 0:
            return f"{text} (default: %(default)s)"
        return text


class Parser(argparse.ArgumentParser):
    """argparse's parser with a "did you mean" for every name typed wrong: a command
    (``conver``), an option (``--fial-on``) or an option's value (``--fail-on warnig``); and an
    unknown option is reported with the usage of the command it was given to."""

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        choices = action.choices
        if choices is None or value in choices:
            return
        names = [str(c) for c in choices]
        raise argparse.ArgumentError(
            action,
            f"invalid choice: {value!r}{did_you_mean(str(value), names)}; "
            f"choose from {', '.join(map(repr, choices))}",
        )

    def parse_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> argparse.Namespace:
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            command = self._command_parser(getattr(parsed, "command", None))
            command.error(command.unknown_arguments(extras))
        return parsed

    def _command_parser(self, name: str | None) -> Parser:
        """The parser of the subcommand ``name`` (this parser when there is none)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction) and name in action.choices:
                return action.choices[name]
        return self

    def unknown_arguments(self, extras: list[str]) -> str:
        """``unrecognized arguments: --fial-on (did you mean '--fail-on'?), x``."""
        known = [s for a in self._actions for s in a.option_strings if s.startswith("--")]
        words = []
        for word in extras:
            option = word.split("=", 1)[0]
            hint = did_you_mean(option, known) if re.match(r"--?[A-Za-z]", option) else ""
            words.append(word + hint)
        noun = "argument" if len(extras) == 1 else "arguments"
        return f"unrecognized {noun}: " + ", ".join(words)


def add_output(p: argparse.ArgumentParser, what: str, required: bool = True, **kw: Any) -> None:
    """``-o OUT, --output OUT``: where the command writes (``what``: "output folder", ...)."""
    p.add_argument("-o", "--output", metavar="OUT", required=required, help=what, **kw)


def add_force(p: argparse.ArgumentParser, what: str = "a non-empty output folder") -> None:
    p.add_argument("--force", action="store_true", help=f"replace {what}")


def add_json(p: argparse.ArgumentParser, what: str = "the report") -> None:
    p.add_argument("--json", action="store_true", help=f"print {what} as JSON on stdout")


def add_fail_on(p: argparse.ArgumentParser | Any, default: str | None = DEFAULT_FAIL_ON) -> None:
    """``--fail-on SEVERITY``: the lowest validation severity that makes the exit code 1."""
    p.add_argument(
        "--fail-on",
        choices=SEVERITIES,
        default=default,
        metavar="SEVERITY",
        help="lowest validation severity that makes the exit code 1: error, warning or info"
        + ("" if default else f" (default: the batch file's, else {DEFAULT_FAIL_ON})"),
    )


def fails(counts: dict[str, int], fail_on: str) -> bool:
    """True when validation ``counts`` hold an issue at or above ``fail_on``."""
    limit = SEVERITIES.index(fail_on)
    return any(int(counts.get(s, 0)) for s in SEVERITIES[: limit + 1])


class DeprecatedAlias(argparse.Action):
    """An old option name kept working: stores into the new option's dest and says, once per
    run, which name to use instead."""

    def __init__(self, option_strings: list[str], dest: str, new: str = "", **kw: Any) -> None:
        self.new = new
        kw.setdefault("help", argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kw)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        problem(f"warning: {option_string} is deprecated; use {self.new}")
        setattr(namespace, self.dest, values)


def add_report(p: argparse.ArgumentParser | Any, what: str, old: str | None = None) -> None:
    """``--report FILE``: write the JSON ``--json`` prints to FILE (``old``: a deprecated
    name of the same option)."""
    p.add_argument("--report", metavar="FILE", help=f"write {what} as JSON to FILE")
    if old:
        p.add_argument(old, dest="report", metavar="FILE", action=DeprecatedAlias, new="--report")
