"""Parameter validators shared by the smoothing methods.

A validator is ``check(name, value) -> value``: it returns the value in canonical form
(a float, a tuple, ...) or raises ``ValueError`` naming the parameter, what was expected
and what was found. Methods declare one per parameter when they register.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from tobitkf.skeleton.topology import GROUP_NAMES

__all__ = [
    "BODY_REGIONS",
    "Validator",
    "as_bool",
    "at_least_int",
    "check_inferred_factor",
    "check_up_axis",
    "limit_vec",
    "nonneg_float",
    "nonneg_or_inf",
    "odd_window",
    "one_of",
    "optional",
    "positive_float",
    "positive_or_inf",
    "positive_vec",
    "region_value",
    "unit_float",
]

Validator = Callable[[str, Any], Any]

#: body regions of the per-region parameters (those of Topology.joint_groups)
BODY_REGIONS = GROUP_NAMES


def _number(name: str, value: Any) -> float:
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None


def positive_float(name: str, value: Any) -> float:
    """A finite number > 0."""
    v = _number(name, value)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return v


def positive_or_inf(name: str, value: Any) -> float:
    """A number > 0; ``inf`` allowed (it switches the bound it sets off)."""
    v = _number(name, value)
    if not v > 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def nonneg_or_inf(name: str, value: Any) -> float:
    """A number >= 0; ``inf`` allowed."""
    v = _number(name, value)
    if not v >= 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return v


def nonneg_float(name: str, value: Any) -> float:
    """A finite number >= 0."""
    v = _number(name, value)
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return v


def unit_float(name: str, value: Any) -> float:
    """A number in [0, 1]."""
    v = nonneg_float(name, value)
    if v > 1:
        raise ValueError(f"{name} must be in [0, 1], got {value!r}")
    return v


def positive_vec(name: str, value: Any) -> Any:
    """A positive number, or 3 of them (x, y, z): a float or a 3-tuple."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number or 3 numbers (x, y, z), got {value!r}") from None
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape[0] != 3):
        raise ValueError(f"{name} must be a number or 3 numbers (x, y, z), got {value!r}")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return float(arr) if arr.ndim == 0 else tuple(float(v) for v in arr)


def limit_vec(name: str, value: Any) -> tuple[float, ...]:
    """3 numbers (one may be given for all), or 2 for a 2-D recording; ±inf allowed, NaN
    not."""
    arr = None
    try:
        a = np.asarray(value, dtype=float)
        arr = a if a.shape == (2,) else np.broadcast_to(a, (3,))
    except (TypeError, ValueError):
        pass
    if arr is None or np.any(np.isnan(arr)):
        raise ValueError(
            f"{name} must be 3 numbers (2 for a 2-D recording; ±inf allowed), got {value!r}"
        )
    return tuple(float(v) for v in arr)


def at_least_int(lo: int) -> Validator:
    """An integer >= ``lo`` (bools refused)."""

    def check(name: str, value: Any) -> int:
        try:
            ok = not isinstance(value, (bool, np.bool_)) and int(value) == value
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok or int(value) < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
        return int(value)

    return check


def int_between(lo: int, hi: int) -> Validator:
    """An integer from ``lo`` to ``hi`` (bools refused)."""
    at_least = at_least_int(lo)

    def check(name: str, value: Any) -> int:
        v = at_least(name, value)
        if v > hi:
            raise ValueError(f"{name} must be an integer from {lo} to {hi}, got {value!r}")
        return v

    return check


def odd_window(name: str, value: Any) -> int:
    """An odd integer >= 1."""
    v = at_least_int(1)(name, value)
    if v % 2 == 0:
        raise ValueError(f"{name} must be odd, got {value!r}")
    return v


def as_bool(name: str, value: Any) -> bool:
    """True or False (not 0/1 or strings)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return bool(value)


def one_of(*choices: str) -> Validator:
    """One of the given strings."""

    def check(name: str, value: Any) -> str:
        if value not in choices:
            raise ValueError(f"{name} must be one of {sorted(choices)}, got {value!r}")
        return str(value)

    return check


def optional(check: Validator) -> Validator:
    """None, or what ``check`` accepts."""
    return lambda name, value: None if value is None else check(name, value)


def over_default(value: Any, default: Any) -> Any:
    """``value`` for a parameter whose default is ``default``: a mapping given for a
    mapping default (a value per body region) overrides only the keys it names."""
    if isinstance(value, Mapping) and isinstance(default, Mapping):
        return {**default, **value}
    return value


def region_value(name: str, value: Any) -> Any:
    """A positive finite number, one for every body region, or per-joint values.

    Per-joint values (an array of shape (J,)) are checked against the topology when the
    method resolves them (:func:`tobitkf.smoothing.robust_gating.region_values`).
    Infinite values are refused in every form: the method refuses them when it resolves
    a number, and a speed or noise of inf in a region made that region's output NaN.
    """
    if isinstance(value, Mapping):
        missing = [g for g in BODY_REGIONS if g not in value]
        extra = sorted(set(value) - set(BODY_REGIONS))
        if missing or extra:
            what = ", ".join(
                [f"missing {missing}"] * bool(missing) + [f"unknown {extra}"] * bool(extra)
            )
            raise ValueError(f"{name} takes a value per body region {BODY_REGIONS}; {what}")
        return {g: positive_float(f"{name}[{g}]", value[g]) for g in BODY_REGIONS}
    if np.ndim(value) > 0:
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            arr = np.full(1, np.nan)
        if arr.ndim != 1 or not np.all(np.isfinite(arr) & (arr > 0)):
            raise ValueError(
                f"{name} must be positive finite numbers, one per joint; got {value!r}"
            )
        return tuple(float(v) for v in arr)
    return positive_float(name, value)


def check_up_axis(value: Any) -> int:
    """0 (x), 1 (y) or 2 (z)."""
    if isinstance(value, bool) or value not in (0, 1, 2):
        raise ValueError(f"up_axis must be 0 (x), 1 (y) or 2 (z), got {value!r}")
    return int(value)


def check_inferred_factor(value: Any) -> float:
    """The INFERRED-joint variance multiplier: finite and >= 1."""
    v = positive_float("inferred_noise_factor", value)
    if v < 1:
        raise ValueError(f"inferred_noise_factor must be >= 1, got {value!r}")
    return v
