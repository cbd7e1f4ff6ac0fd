"""How close a net's principal curvatures lie to a Weingarten relation F(k1, k2) = 0."""

from __future__ import annotations

import numpy as np

__all__ = ["weingarten_fit"]


def weingarten_fit(k1: np.ndarray, k2: np.ndarray) -> dict:
    """How close curvature pairs lie to a one-parameter family ``F(k1, k2) = 0``.

    Fits the line ``a k1 + b k2 = c`` (``a^2 + b^2 = 1``) by total least squares, and a
    conic by its algebraic fit measured with geometric (first-order) distances.

    Parameters
    ----------
    k1, k2 : (p,) float, principal curvatures (any unit; the results are in the same).

    Returns
    -------
    dict with ``line`` (``a``, ``b``, ``c``), ``line_residual_rms``, ``line_residual_max``,
    ``conic_residual_rms``, ``spread`` (standard deviation along the line) and
    ``thickness`` (``line_residual_rms / spread``: near 0 for a Weingarten surface, of the
    order of 1 when the pairs fill a region).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 1.0, 50)
    >>> fit = weingarten_fit(0.5 + t, 0.2 - 2 * t)   # 2 k1 + k2 = 1.2
    >>> round(fit["line_residual_rms"], 12), round(abs(fit["line"]["c"] / fit["line"]["b"]), 6)
    (0.0, 1.2)
    """
    K = np.column_stack([k1, k2]).astype(np.float64)
    K = K[np.all(np.isfinite(K), axis=1)]
    if len(K) < 3:
        return {"line": None, "line_residual_rms": None, "line_residual_max": None,
                "conic_residual_rms": None, "spread": None, "thickness": None}
    centre = K.mean(axis=0)
    _, sv, vt = np.linalg.svd(K - centre, full_matrices=False)
    direction, normal = vt[0], vt[1]
    if normal[0] < 0 or (normal[0] == 0 and normal[1] < 0):
        normal = -normal
    residual = (K - centre) @ normal
    spread = float(np.std((K - centre) @ direction))
    # conic: scale to unit size for conditioning, algebraic fit, first-order distances
    size = float(np.abs(K - centre).max()) or 1.0
    x, y = ((K - centre) / size).T
    D = np.column_stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    coef = np.linalg.svd(D, full_matrices=False)[2][-1]
    F = D @ coef
    grad = np.hypot(2 * coef[0] * x + coef[1] * y + coef[3], coef[1] * x + 2 * coef[2] * y + coef[4])
    with np.errstate(divide="ignore", invalid="ignore"):
        conic = np.where(grad > 0, np.abs(F) / grad, np.inf) * size
    rms = float(np.sqrt(np.mean(residual**2)))
    return {
        "line": {"a": float(normal[0]), "b": float(normal[1]), "c": float(centre @ normal)},
        "line_residual_rms": rms,
        "line_residual_max": float(np.abs(residual).max()),
        "conic_residual_rms": float(np.sqrt(np.mean(np.minimum(conic, np.abs(residual)) ** 2))),
        "spread": spread,
        "thickness": rms / spread if spread > 0 else None,
    }
