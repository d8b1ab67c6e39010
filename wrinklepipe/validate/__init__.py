"""``validate-asset``: coded rules, the GPU render pass and the reports.

Public API::

    from wrinklepipe.sources.validation import load_input   # the sources layer, above this one
    from wrinklepipe.validate import validate, ValidateOptions
    inp = load_input(path)                # folder, glTF/GLB, USD, manifest, bundle, demo
    report = validate(inp, ValidateOptions())
    report.issues, report.counts, report.exit_code("error")
"""

from __future__ import annotations

from wrinklepipe.validate.catalogue import RULES, RULES_BY_CODE, Issue, Rule
from wrinklepipe.validate.config import Config, load_config
from wrinklepipe.validate.context import ValidateOptions
from wrinklepipe.validate.inputs import ChannelEntry, Texture, ValidationInput
from wrinklepipe.validate.run import Report, validate

__all__ = [
    "RULES",
    "RULES_BY_CODE",
    "ChannelEntry",
    "Config",
    "Issue",
    "Report",
    "Rule",
    "Texture",
    "ValidateOptions",
    "ValidationInput",
    "load_config",
    "validate",
]
