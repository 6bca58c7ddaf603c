"""Short, informative ``repr`` for the result dataclasses.

The default dataclass ``repr`` prints every array element and every function object, which
buries the result in a notebook or a log. :func:`compact_repr` prints scalars and short
strings as they are, arrays as ``<array shape dtype>`` (with their value when they hold a
single number), long sequences as ``<N items>``, functions by name and nested results by
their class name, one level deep. Classes use it with ``__repr__ = compact_repr``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["compact_repr"]

_MAX_ITEMS = 4  # sequences longer than this are shown by their length
_MAX_STR = 60  # strings longer than this are shortened


def _short(value: Any, depth: int) -> str:
    if value is None or isinstance(value, bool | int):
        return repr(value)
    if isinstance(value, float | np.floating):
        return f"{float(value):.6g}"
    if isinstance(value, complex | np.complexfloating):
        return f"{complex(value):.6g}"
    if isinstance(value, str):
        text = str(value)
        return repr(text if len(text) <= _MAX_STR else text[: _MAX_STR - 3] + "...")
    if isinstance(value, np.ndarray):
        if value.size == 1:
            return _short(value.reshape(()).item(), depth)
        return f"<array {'x'.join(map(str, value.shape))} {value.dtype}>"
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return f"<{type(value).__name__}>" if depth > 0 else compact_repr(value)
    if isinstance(value, Mapping):
        if len(value) > _MAX_ITEMS:
            return f"<{len(value)} entries>"
        return "{" + ", ".join(f"{k!r}: {_short(v, depth + 1)}" for k, v in value.items()) + "}"
    if isinstance(value, list | tuple):
        if len(value) > _MAX_ITEMS:
            return f"<{len(value)} items>"
        inner = ", ".join(_short(v, depth + 1) for v in value)
        if isinstance(value, list):
            return f"[{inner}]"
        return f"({inner},)" if len(value) == 1 else f"({inner})"
    if isinstance(value, Callable):
        return getattr(value, "__qualname__", getattr(value, "__name__", type(value).__name__))
    return f"<{type(value).__name__}>"


def compact_repr(self: Any) -> str:
    """``ClassName(field=value, ...)`` over the dataclass fields shown in the repr, with
    arrays, long sequences, functions and nested results summarised (see the module)."""
    parts = []
    for f in dataclasses.fields(self):
        if not f.repr or f.name.startswith("_"):
            continue
        parts.append(f"{f.name}={_short(getattr(self, f.name), 1)}")
    return f"{type(self).__name__}({', '.join(parts)})"
