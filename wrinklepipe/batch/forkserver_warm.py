"""Imported by the batch fork server (``engines._PRELOAD``): builds, once, what every asset's
forked process would otherwise build again before its first block encoding (quicktex's BC1 /
BC3 encoder tables, ~0.1 s per asset). Importing it creates no thread and no GL context."""

from __future__ import annotations

from wrinklepipe.normals import compress

compress.keep_quicktex_encoders()
