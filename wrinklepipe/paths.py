"""Where the project's non-Python files live (schemas, shaders), relative to the package."""

from __future__ import annotations

from pathlib import Path

#: The source tree root: the folder holding ``wrinklepipe/``, ``schemas/``, ``shaders/``.
ROOT = Path(__file__).resolve().parent.parent
SCHEMAS_DIR = ROOT / "schemas"
SHADERS_DIR = ROOT / "shaders"
FIXTURES_DIR = ROOT / "fixtures"
