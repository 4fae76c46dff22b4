"""Input validation shared by the kinematics package: precise errors at the boundary."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def as_float_array(name: str, value: Any) -> FloatArray:
    """Convert ``value`` to a float64 array or raise a ``TypeError`` naming ``name``.

    Args:
        name: The quantity's name, used in the error message.
        value: Anything array-like of real numbers.

    Returns:
        A float64 array (a copy only where a conversion was needed).

    Raises:
        TypeError: If ``value`` is not an array of real numbers.
    """
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - exotic objects
        raise TypeError(f"{name} must be an array of real numbers, got {type(value).__name__}") from exc
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise TypeError(f"{name} must be an array of real numbers, got dtype {arr.dtype}")
    if np.iscomplexobj(arr):
        raise TypeError(f"{name} must be real, got complex dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


def check_finite(name: str, arr: FloatArray) -> None:
    """Raise a ``ValueError`` if ``arr`` holds a NaN or an infinity.

    Args:
        name: The quantity's name, used in the error message.
        arr: The array to check, any shape.

    Raises:
        ValueError: Naming how many entries are non-finite and the first of them.
    """
    finite = np.isfinite(arr)
    if not finite.all():
        bad = np.argwhere(~finite)
        first = tuple(int(i) for i in bad[0])
        raise ValueError(
            f"{name} must be finite, got {len(bad)} non-finite value(s), first {arr[first]!r} at index {first}"
        )


def batch_vector(name: str, value: Any, size: int, what: str) -> FloatArray:
    """Validate a batch of vectors of length ``size``: shape (..., size), finite reals.

    Args:
        name: The quantity's name, used in error messages.
        value: Array-like of shape (..., size).
        size: The required length of the last axis.
        what: A short description of the components (for example "(L_1, L_2, L_3) [m]").

    Returns:
        A float64 array of shape (..., size).

    Raises:
        TypeError: If ``value`` is not real-valued.
        ValueError: On a wrong shape or a non-finite entry.
    """
    arr = value if type(value) is np.ndarray and value.dtype == np.float64 else as_float_array(name, value)
    if arr.ndim == 0 or arr.shape[-1] != size:
        raise ValueError(f"{name} must have shape (..., {size}) holding {what}, got shape {arr.shape}")
    flat = arr.ravel()
    # Cheap test, exact check only on alarm. A large np.dot goes to multithreaded BLAS, which can cost
    # milliseconds on a busy or small machine, so large batches use np.isfinite instead.
    if not (math.isfinite(float(np.dot(flat, flat))) if flat.size <= 1024 else np.isfinite(flat).all()):
        check_finite(name, arr)
    return arr


def per_leg(name: str, value: Any, n: int) -> FloatArray:
    """A scalar or a length-n array of finite reals, as a float64 array of shape (n,) (one value per leg)."""
    arr = as_float_array(name, value)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a number or have shape ({n},), got shape {arr.shape}")
    check_finite(name, arr)
    return np.array(arr, dtype=np.float64)


def point_set(name: str, value: Any, count: int, dim: int) -> FloatArray:
    """Validate a set of ``count`` points in ``dim`` dimensions: shape (count, dim), finite reals.

    Args:
        name: The quantity's name, used in error messages.
        value: Array-like of shape (count, dim).
        count: The number of points.
        dim: The dimension of each point.

    Returns:
        A read-only float64 array of shape (count, dim).

    Raises:
        TypeError: If ``value`` is not real-valued.
        ValueError: On a wrong shape or a non-finite entry.
    """
    arr = np.array(as_float_array(name, value), dtype=np.float64, copy=True)
    if arr.shape != (count, dim):
        raise ValueError(f"{name} must have shape ({count}, {dim}), got {arr.shape}")
    check_finite(name, arr)
    arr.setflags(write=False)
    return arr


def positive_scalar(name: str, value: Any) -> float:
    """Validate a finite, strictly positive real scalar.

    Args:
        name: The quantity's name, used in error messages.
        value: The candidate value.

    Returns:
        The value as a Python float.

    Raises:
        TypeError: If ``value`` is not a real number.
        ValueError: If it is not finite or not > 0.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def check_distinct(name: str, points: FloatArray) -> None:
    """Raise a ``ValueError`` naming the first pair of coincident points of a set, shape (n, d) [m]."""
    extent = max(1.0, float(np.max(np.abs(points))))
    for i in range(len(points)):
        for j in range(i + 1, len(points)):
            gap = float(np.linalg.norm(points[i] - points[j]))
            if gap <= 1e-9 * extent:
                raise ValueError(
                    f"{name} must be pairwise distinct: points {i + 1} and {j + 1} are {gap:.3g} m "
                    f"apart ({points[i].tolist()} and {points[j].tolist()})"
                )
