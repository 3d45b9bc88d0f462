"""Checks of user input that several modules share."""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any


def as_whole(value: Any) -> int | None:
    """``value`` as an int if it is a whole number (an integer, numpy's
    included, or a finite float with no fraction; never a bool), else None."""
    if isinstance(value, bool) or not isinstance(value, Real):
        return None
    if isinstance(value, Integral):
        return int(value)
    return int(value) if math.isfinite(value) and float(value).is_integer() else None
