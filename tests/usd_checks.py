"""UsdValidation for the tests, one rule for every USD output.

usd-core (the project's pxr) has no UsdMtlx, so its shader registry knows none of MaterialX's
node definitions: its ``ShaderSdrCompliance`` validator reports every ``ND_...`` shader id of
the wrinkle material's MaterialX network as "not found in sdrRegistry". Those reports, and only
those, are left out here when pxr has no UsdMtlx; tests/test_blender.py validates the same
outputs with Blender 5's pxr, which has UsdMtlx, and asserts 0 errors of any kind.
"""

from __future__ import annotations

import re
from typing import Any

from pxr import UsdValidation

try:
    from pxr import UsdMtlx  # noqa: F401

    HAS_USDMTLX = True
except ImportError:
    HAS_USDMTLX = False

_UNKNOWN_MTLX_ID = re.compile(r"^shaderId 'ND_\w+' specified on shader prim <[^>]+> not found")


def unknown_materialx_id(error: Any) -> bool:
    """``error`` only says a MaterialX node id is unknown to a registry without UsdMtlx."""
    return not HAS_USDMTLX and bool(_UNKNOWN_MTLX_ID.match(error.GetMessage()))


def validation_errors(stage: Any) -> list[Any]:
    """UsdValidation's errors (severity Error) on ``stage``, all validators, but
    :func:`unknown_materialx_id` ones."""
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    return [
        e
        for e in UsdValidation.ValidationContext(validators).Validate(stage)
        if e.GetType() == UsdValidation.ValidationErrorType.Error and not unknown_materialx_id(e)
    ]
