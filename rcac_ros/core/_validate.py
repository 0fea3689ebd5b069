"""Argument checks shared by the entry points of the core (run once, never per kernel call)."""

import numpy as np

from rcac_ros.errors import GainError, InputError


def as_array(value, shape, name, exc=InputError):
    """Return ``value`` as a C-contiguous float64 array of ``shape``, finite, or raise ``exc``.

    ``shape`` may contain ``None`` for a free dimension.
    """
    arr = numeric(value, name, exc)
    if arr.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, arr.shape)):
        want = "x".join("*" if s is None else str(s) for s in shape) or "scalar"
        raise exc(f"{name}: expected shape ({want}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise exc(f"{name}: contains NaN or Inf")
    return np.ascontiguousarray(arr)


def numeric(value, name, exc=InputError):
    """``value`` as a float64 array, or ``exc`` naming the field (no finiteness check)."""
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise exc(f"{name}: not a numeric array ({err})") from None


def scalar(value, name, exc=InputError, minimum=None, strict=False):
    """A finite float, at least (``strict``: above) ``minimum`` if given, or ``exc``."""
    if isinstance(value, (str, bytes)):
        raise exc(f"{name}: expected a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise exc(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise exc(f"{name}: must be finite, got {value!r}")
    if minimum is not None and (v < minimum or (strict and v == minimum)):
        raise exc(f"{name}: must be {'>' if strict else '>='} {minimum}, got {value!r}")
    return v


def joint_values(value, n, name, exc=InputError, finite=True):
    """A scalar or an (n,) vector as an (n,) float64 array (Inf allowed unless ``finite``)."""
    arr = numeric(value, name, exc)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise exc(f"{name}: expected a scalar or {n} values, got shape {arr.shape}")
    if np.any(np.isnan(arr)) or (finite and not np.all(np.isfinite(arr))):
        raise exc(f"{name}: contains NaN{' or Inf' if finite else ''}")
    return arr


def check_spd(mat, name, exc):
    """Raise ``exc`` unless ``mat`` is symmetric positive definite."""
    if not np.allclose(mat, mat.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(mat).max())):
        raise exc(f"{name}: not symmetric")
    try:
        np.linalg.cholesky(mat)
    except np.linalg.LinAlgError:
        raise exc(f"{name}: not positive definite") from None


def per_link_matrix(value, n, size, name, exc):
    """Broadcast a scalar, a (size,) diagonal, a (size, size) matrix or an (n, size, size) stack.

    Every block must be symmetric positive definite. Returns an (n, size, size) array.
    """
    arr = numeric(value, name, exc)
    if arr.ndim == 0:
        arr = np.eye(size) * arr
    elif arr.shape == (size,):
        arr = np.diag(arr)
    if arr.shape == (size, size):
        arr = np.broadcast_to(arr, (n, size, size))
    arr = as_array(arr, (n, size, size), name, exc)
    for i in range(n):
        check_spd(arr[i], f"{name}[{i}]", exc)
    return arr


def positive_vector(value, n, name, exc):
    """Broadcast a scalar or an (n,) vector (or a diagonal matrix) of strictly positive entries."""
    arr = numeric(value, name, exc)
    if arr.ndim == 2:
        if arr.shape != (n, n) or np.any(arr - np.diag(np.diag(arr))):
            raise exc(f"{name}: must be a scalar, a vector of {n} or a diagonal {n}x{n} matrix")
        arr = np.diag(arr)
    arr = joint_values(arr, n, name, exc)
    if np.any(arr <= 0.0):
        raise exc(f"{name}: every entry must be > 0, got {arr.tolist()}")
    return arr


def joint_vectors(n, **vectors):
    """Validate named joint-space vectors of length ``n`` (entry-point checks)."""
    return [as_array(v, (n,), k) for k, v in vectors.items()]


def projection_bounds(theta_bounds, n):
    """``(theta_min, theta_max)`` (n, 13) of the projection option ``theta_bounds``: None
    (none: ``(None, None)``), ``"mass"`` or a pair of bounds (each a scalar, (13,) or
    (n, 13)); every mass >= 0 in either case. Raises :class:`GainError` naming the field."""
    if theta_bounds is None:
        return None, None
    if isinstance(theta_bounds, str):
        if theta_bounds != "mass":
            raise GainError(f"theta_bounds: expected None, 'mass' or (theta_min, "
                            f"theta_max), got {theta_bounds!r}")
        lo, hi = np.full((n, 13), -np.inf), np.full((n, 13), np.inf)
    else:
        try:
            lo, hi = theta_bounds
        except (TypeError, ValueError):
            raise GainError("theta_bounds: expected None, 'mass' or (theta_min, "
                            "theta_max)") from None
        lo, hi = _bound(lo, "theta_min", n), _bound(hi, "theta_max", n)
        if np.any(lo > hi):
            raise GainError("theta_bounds: theta_min > theta_max somewhere")
    lo[:, 0] = np.maximum(lo[:, 0], 0.0)          # mass >= 0
    if np.any(hi[:, 0] < 0.0):
        raise GainError("theta_bounds: theta_max of a mass is < 0")
    return lo, hi


def _bound(value, name, n):
    try:
        arr = np.broadcast_to(np.asarray(value, dtype=float), (n, 13)).copy()
    except (TypeError, ValueError):
        raise GainError(f"{name}: expected a scalar, (13,) or ({n}, 13) values") from None
    if np.any(np.isnan(arr)):
        raise GainError(f"{name}: contains NaN")
    return arr
