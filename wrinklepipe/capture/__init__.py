"""Wrinkle normal maps from two flash-lit photographs (Dutreve et al., section 3).

:func:`capture` runs the stage on arrays; :mod:`.landmarks` reads landmark files; :mod:`.warp`,
:mod:`.ratio` and :mod:`.orientation` are its steps; :mod:`.synthetic` renders a session with
known truth and :mod:`.evaluate` scores a result against it; :mod:`.report` writes the report.
"""

from wrinklepipe.capture.orientation import METHODS, OrientationOptions
from wrinklepipe.capture.pipeline import CaptureOptions, CaptureResult, capture
from wrinklepipe.capture.ratio import RatioOptions

__all__ = [
    "METHODS",
    "CaptureOptions",
    "CaptureResult",
    "OrientationOptions",
    "RatioOptions",
    "capture",
]
