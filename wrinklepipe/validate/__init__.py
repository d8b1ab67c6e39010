"""``validate-asset``: coded rules, the GPU render pass and the reports.

Public API::

    from wrinklepipe.validate import validate, load_input, ValidateOptions, write_reports
    inp = load_input(path)                # folder, glTF/GLB, USD, manifest, bundle
    report = validate(inp, ValidateOptions())
    report.issues, report.counts, report.exit_code("error")
"""

from __future__ import annotations

from wrinklepipe.validate.catalogue import RULES, RULES_BY_CODE, Issue, Rule
from wrinklepipe.validate.config import Config, load_config
from wrinklepipe.validate.context import ValidateOptions
from wrinklepipe.validate.inputs import ChannelEntry, Texture, ValidationInput
from wrinklepipe.validate.loader import LoadOptions, load_input
from wrinklepipe.validate.run import Report, validate

__all__ = [
    "RULES",
    "RULES_BY_CODE",
    "ChannelEntry",
    "Config",
    "Issue",
    "LoadOptions",
    "Report",
    "Rule",
    "Texture",
    "ValidateOptions",
    "ValidationInput",
    "load_config",
    "load_input",
    "validate",
]
