"""``wrinklepipe --help`` lists every environment variable the package reads (found here by
scanning the package's source for ``"WRINKLEPIPE_..."`` names, not from the list itself)."""

from __future__ import annotations

import re

from wrinklepipe.cli import build_parser
from wrinklepipe.paths import ROOT

#: Names that are not settings: a shader keyword the generated HLSL defines, and the size list
#: only `bench scale` reads (docs/scale.md).
NOT_SETTINGS = {"WRINKLEPIPE_WRINKLE", "WRINKLEPIPE_SCALE_SIZES"}


def test_help_lists_every_environment_variable_read() -> None:
    read = set()
    for path in (ROOT / "wrinklepipe").rglob("*.py"):
        read |= set(re.findall(r"[\"'](WRINKLEPIPE_[A-Z_]+)[\"']", path.read_text("utf-8")))
    assert {"WRINKLEPIPE_WORKING_SET", "WRINKLEPIPE_SCRATCH"} <= read  # the scan finds them
    shown = build_parser().format_help()
    missing = sorted(name for name in read - NOT_SETTINGS if name not in shown)
    assert not missing, f"wrinklepipe --help does not name {missing}"
