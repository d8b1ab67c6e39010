"""The validator's config file: ignore codes, change their severity, tune options.

TOML or JSON, either at the top level or under ``[validate]``::

    ignore = ["WP-TEX-007"]            # codes dropped from the report
    [severity]                         # code -> "error" | "warning" | "info"
    "WP-MASK-003" = "error"
    [options]                          # any ValidateOptions field
    render_size = 256

The Khronos glTF-Validator's JSON keys are accepted too: ``ignoredIssues`` and
``severityOverrides`` (0 error, 1 warning, 2 information; 3 ignores the code).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wrinklepipe.errors import InputError, Problem
from wrinklepipe.io.json_safe import loads_json, loads_toml
from wrinklepipe.validate.catalogue import RULES_BY_CODE, SEVERITIES, Issue
from wrinklepipe.validate.context import ValidateOptions

_KHRONOS_SEVERITY = {0: "error", 1: "warning", 2: "info"}


@dataclass
class Config:
    ignore: frozenset[str] = frozenset()
    severity: dict[str, str] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)

    def apply(self, issues: list[Issue]) -> tuple[list[Issue], int]:
        """Issues after ignores and severity overrides, and how many were ignored."""
        out = []
        dropped = 0
        for i in issues:
            if i.code in self.ignore:
                dropped += 1
                continue
            if i.code in self.severity:
                i.severity = self.severity[i.code]
            out.append(i)
        return out, dropped

    def validate_options(self, base: ValidateOptions | None = None) -> ValidateOptions:
        return dataclasses.replace(base or ValidateOptions(), **self.options)

    def run_options(
        self, render: bool = True, render_size: int | None = None
    ) -> tuple[ValidateOptions, Config]:
        """What one validation runs with: the options this config sets, the command line's
        ``render`` (False turns the render pass off) and ``render_size`` (when given) over
        them; and the config that is left to apply to the issues (ignores and severities:
        its options are in the first). ``validate-asset`` and a batch worker both use it."""
        options = self.validate_options(ValidateOptions())
        if not render:
            options = dataclasses.replace(options, render=False)
        if render_size:
            options = dataclasses.replace(options, render_size=int(render_size))
        return options, Config(self.ignore, self.severity, {})


def parse_config(data: dict[str, Any], file: str = "<config>") -> Config:
    """A :class:`Config` from parsed TOML/JSON; every problem reported at once."""
    problems: list[Problem] = []
    if not isinstance(data, dict):
        raise InputError([Problem(file, "config must be a table / object")])
    if isinstance(data.get("validate"), dict):
        data = data["validate"]
    elif isinstance(data.get("validation"), dict):
        data = data["validation"]
    ignore = list(data.get("ignore", [])) + list(data.get("ignoredIssues", []))
    severity: dict[str, str] = {}
    for code, sev in dict(data.get("severity", {})).items():
        severity[code] = sev
    for code, sev in dict(data.get("severityOverrides", {})).items():
        if sev == 3:
            ignore.append(code)
        else:
            severity[code] = _KHRONOS_SEVERITY.get(sev, str(sev))
    for code in ignore:
        if code not in RULES_BY_CODE:
            problems.append(Problem(file, f"unknown issue code {code!r}", "ignore"))
    for code, sev in severity.items():
        if code not in RULES_BY_CODE:
            problems.append(Problem(file, f"unknown issue code {code!r}", f"severity.{code}"))
        if sev not in SEVERITIES:
            problems.append(
                Problem(file, f"severity {sev!r} is not one of {', '.join(SEVERITIES)}", code)
            )
    fields = {f.name: f for f in dataclasses.fields(ValidateOptions)}
    options = dict(data.get("options", {}))
    for k in options:
        if k not in fields:
            problems.append(Problem(file, f"unknown option {k!r}", f"options.{k}"))
    known = {"ignore", "ignoredIssues", "severity", "severityOverrides", "options"}
    known |= {"maxIssues", "maxEntries", "onlyIssues"}
    for k in data:
        if k not in known:
            problems.append(Problem(file, f"unknown key {k!r}", k))
    if problems:
        raise InputError(problems)
    return Config(frozenset(ignore), severity, options)


def load_config(path: str | Path) -> Config:
    """Read a TOML (``.toml``) or JSON config file."""
    p = Path(path)
    if not p.is_file():
        raise InputError([Problem(str(p), "config file not found")])
    text = p.read_bytes()
    if p.suffix.lower() == ".json":
        data = loads_json(text, p, "config JSON")
    else:
        try:
            data = loads_toml(text.decode("utf-8"), p, "config TOML")
        except UnicodeDecodeError:
            raise InputError([Problem(str(p), "config is not UTF-8 text")]) from None
    return parse_config(data, str(p))
