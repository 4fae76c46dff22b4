"""Batched small dense linear algebra: solves, determinants and conditioning over stacks of matrices."""

from __future__ import annotations

import math

import numpy as np

from kinematics._validation import FloatArray

__all__ = ["batched_solve", "determinant", "hadamard_ratio", "singular_value_ratio", "solve3_with_hadamard"]

#: Batches at least this large use the closed-form 3×3 adjugate instead of LAPACK.
_ADJUGATE_MIN_BATCH = 16


def _adjugate3(A: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Adjugate and determinant of each 3×3 matrix: A⁻¹ = adj(A)/det(A).

    Args:
        A: Matrices, shape (..., 3, 3).

    Returns:
        (adj(A) of shape (..., 3, 3), det(A) of shape (...)).
    """
    a00, a01, a02 = A[..., 0, 0], A[..., 0, 1], A[..., 0, 2]
    a10, a11, a12 = A[..., 1, 0], A[..., 1, 1], A[..., 1, 2]
    a20, a21, a22 = A[..., 2, 0], A[..., 2, 1], A[..., 2, 2]
    adj = np.empty(A.shape)
    adj[..., 0, 0] = a11 * a22 - a12 * a21
    adj[..., 1, 0] = a12 * a20 - a10 * a22
    adj[..., 2, 0] = a10 * a21 - a11 * a20
    adj[..., 0, 1] = a02 * a21 - a01 * a22
    adj[..., 1, 1] = a00 * a22 - a02 * a20
    adj[..., 2, 1] = a01 * a20 - a00 * a21
    adj[..., 0, 2] = a01 * a12 - a02 * a11
    adj[..., 1, 2] = a02 * a10 - a00 * a12
    adj[..., 2, 2] = a00 * a11 - a01 * a10
    det = a00 * adj[..., 0, 0] + a01 * adj[..., 1, 0] + a02 * adj[..., 2, 0]
    return adj, det


def _solve3_single(A: FloatArray, B: FloatArray) -> FloatArray:
    """One 3×3 system by the closed-form adjugate on Python floats (faster than a LAPACK call)."""
    return solve3_with_hadamard(A, B)[0]


def solve3_with_hadamard(
    A: FloatArray, B: FloatArray, column_scale: FloatArray | None = None
) -> tuple[FloatArray, float]:
    """Solve one 3×3 system A X = B and give the Hadamard ratio of A · diag(column_scale), sharing the work.

    Args:
        A: One matrix, shape (3, 3).
        B: Right-hand sides, shape (3, r).
        column_scale: Positive column factors for the ratio, shape (3,); default all ones.

    Returns:
        (X of shape (3, r), all-NaN if A is exactly singular; the ratio in [0, 1] as in ``hadamard_ratio``).
    """
    (a, b, c), (d, e, f), (g, h, i) = A.tolist()
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    c10, c11, c12 = f * g - d * i, a * i - c * g, c * d - a * f
    c20, c21, c22 = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * c00 + b * c10 + c * c20
    u, v, w = (1.0, 1.0, 1.0) if column_scale is None else column_scale.tolist()
    norms = math.sqrt(
        ((a * u) ** 2 + (b * v) ** 2 + (c * w) ** 2)
        * ((d * u) ** 2 + (e * v) ** 2 + (f * w) ** 2)
        * ((g * u) ** 2 + (h * v) ** 2 + (i * w) ** 2)
    )
    ratio = abs(det * u * v * w) / norms if norms > 0 else 0.0
    if det == 0.0 or not math.isfinite(det):
        return np.full(B.shape, np.nan), ratio
    return np.array([[c00, c01, c02], [c10, c11, c12], [c20, c21, c22]]) @ B / det, ratio


def determinant(A: FloatArray) -> FloatArray:
    """det(A) of each square matrix of a batch.

    Args:
        A: Matrices, shape (..., k, k).

    Returns:
        det(A), shape (...).
    """
    if A.shape[-2:] == (3, 3) and A.ndim > 2:
        return _adjugate3(A)[1]
    return np.linalg.det(A)


def batched_solve(A: FloatArray, B: FloatArray) -> FloatArray:
    """Solve A X = B for each matrix of a batch; NaN (never an exception) where A is exactly singular.

    A single 3×3 system and large batches of them use the closed-form adjugate (faster than a LAPACK
    call per matrix); everything else uses ``numpy.linalg.solve`` (LU with partial pivoting).

    Args:
        A: Square matrices, shape (..., k, k).
        B: Right-hand sides, shape (..., k, r) (add a trailing axis for vectors); broadcasts with A.

    Returns:
        X, shape (..., k, r); all-NaN for the matrices of the batch that are exactly singular.
    """
    batch = A.shape[:-2]
    if A.shape == (3, 3) and B.ndim == 2:
        return _solve3_single(A, B)
    if A.ndim == 2 and B.ndim == 2:
        try:
            return np.linalg.solve(A, B)
        except np.linalg.LinAlgError:
            return np.full(B.shape, np.nan)
    if A.shape[-2:] == (3, 3) and math.prod(batch) >= _ADJUGATE_MIN_BATCH:
        adj, det = _adjugate3(A)
        with np.errstate(divide="ignore", invalid="ignore"):
            X = np.matmul(adj, B) / det[..., None, None]
        X[det == 0] = np.nan
        return X
    try:
        return np.linalg.solve(A, B)
    except np.linalg.LinAlgError:
        shape = np.broadcast_shapes(batch, B.shape[:-2])
        A_flat = np.broadcast_to(A, shape + A.shape[-2:]).reshape((-1,) + A.shape[-2:])
        B_flat = np.broadcast_to(B, shape + B.shape[-2:]).reshape((-1,) + B.shape[-2:])
        out = np.full(B_flat.shape, np.nan)
        for i in range(A_flat.shape[0]):
            try:
                out[i] = np.linalg.solve(A_flat[i], B_flat[i])
            except np.linalg.LinAlgError:
                pass
        return out.reshape(shape + B.shape[-2:])


def hadamard_ratio(A: FloatArray, column_scale: FloatArray | None = None) -> FloatArray:
    """|det Â| / ∏_i ‖row_i(Â)‖ of Â = A · diag(column_scale): 1 for orthogonal rows, 0 iff A is singular.

    Invariant to scaling each row, so constraints with different units or magnitudes weigh alike;
    ``column_scale`` makes columns of different units commensurate.

    Args:
        A: Square matrices, shape (..., k, k).
        column_scale: Positive column factors, shape (k,); default all ones.

    Returns:
        Ratio in [0, 1], shape (...); 0 for a matrix with a zero row.
    """
    if A.shape == (3, 3):  # one matrix: Python floats beat a dozen tiny array operations
        (a, b, c), (d, e, f), (g, h, i) = A.tolist()
        if column_scale is not None:
            u, v, w = column_scale.tolist()
            a, d, g, b, e, h, c, f, i = a * u, d * u, g * u, b * v, e * v, h * v, c * w, f * w, i * w
        det = abs(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g))
        norms = math.sqrt((a * a + b * b + c * c) * (d * d + e * e + f * f) * (g * g + h * h + i * i))
        return np.float64(det / norms if norms > 0 else 0.0)
    if column_scale is not None:
        A = A * column_scale
    norms = np.sqrt(np.prod(np.einsum("...ij,...ij->...i", A, A), axis=-1))
    det = np.abs(determinant(A))
    return np.divide(det, norms, out=np.zeros_like(det), where=norms > 0)


def singular_value_ratio(M: FloatArray) -> FloatArray:
    """Inverse condition number σ_min/σ_max of each matrix of a batch.

    Args:
        M: Matrices, shape (..., r, c).

    Returns:
        σ_min/σ_max in [0, 1], shape (...). 0 for a zero matrix.
    """
    sigma = np.linalg.svd(M, compute_uv=False)
    top = sigma[..., 0]
    return np.divide(sigma[..., -1], top, out=np.zeros_like(top), where=top > 0)
