"""What C libraries say on their own, kept off the terminal: the one line the tool prints.

libpng writes "libpng error: ..." straight to file descriptor 2 when OpenImageIO reads a damaged
PNG; OpenImageIO reports the same through ``geterror()``, which the readers turn into their one
message (:func:`oiio_message`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator


@contextlib.contextmanager
def native_stderr_silenced() -> Iterator[None]:
    """Keep what C libraries print straight to file descriptor 2 (libpng's "libpng error: ...")
    off the terminal while a file is opened or decoded: OpenImageIO reports the same through
    geterror(), which the tool turns into its one message."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def oiio_message(text: str) -> str:
    """OpenImageIO's error text on one line (it may hold several)."""
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return "; ".join(dict.fromkeys(lines)) or "unrecognised or truncated image"
