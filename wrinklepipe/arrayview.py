"""Objects that hold an array in another form (integers, boxes) and are seen as its float32.

:class:`FloatView` gives such an object numpy's operators, ufuncs and array functions on the
float32 array it stands for (``np.asarray(view)``, its ``__array__``): ``view * 2``,
``np.clip(view, 0, 1)``, ``np.stack(list_of_views)``. A subclass defines ``__array__`` and,
for what it can do without the whole array, its own indexing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.lib.mixins import NDArrayOperatorsMixin


class FloatView(NDArrayOperatorsMixin):
    """Operators, ufuncs and array functions on ``np.asarray(self)``."""

    __array_priority__ = 20.0

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        raise NotImplementedError

    def __array_ufunc__(self, ufunc: Any, method: str, *inputs: Any, **kwargs: Any) -> Any:
        if "out" in kwargs:
            kwargs["out"] = tuple(_plain(o) for o in kwargs["out"])
        return getattr(ufunc, method)(*(_plain(x) for x in inputs), **kwargs)

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        return func(
            *(_plain(a, True) for a in args), **{k: _plain(v, True) for k, v in kwargs.items()}
        )


def _plain(x: Any, nested: bool = False) -> Any:
    """``x`` as numpy sees it: a view's float32 array (in lists and tuples too, ``nested``)."""
    if isinstance(x, FloatView):
        return np.asarray(x)
    if nested and isinstance(x, list | tuple):
        return type(x)(_plain(v, True) for v in x)
    return x
