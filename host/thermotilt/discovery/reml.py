"""The restricted (REML) log-likelihood's parts for Gaussian data with a
known covariance and fixed effects integrated out (Harville, JASA 72,
1977), shared by the fits of undeclared noise (channel.py) and of the
chamber's floor (chamber_floor.py). Written here because statsmodels'
REML (MixedLM) takes only random effects, not a given covariance."""

from __future__ import annotations

import numpy as np
from scipy.linalg import cholesky, qr, solve_triangular


def restricted_parts(covariance: np.ndarray, design: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """log|V| + log|X'V⁻¹X| and the GLS residual's squared norm
    y'V⁻¹y − (its projection on the design): -2 log restricted likelihood is
    their sum up to a constant. Raises numpy's LinAlgError where the
    covariance is not positive definite."""
    lower = cholesky(covariance, lower=True)
    whitened_values = solve_triangular(lower, values, lower=True)
    whitened_design = solve_triangular(lower, design, lower=True)
    q, r = qr(whitened_design, mode="economic")
    left = whitened_values - q @ (q.T @ whitened_values)
    log_det = 2.0 * float(np.sum(np.log(np.diag(lower)))) + 2.0 * float(np.sum(np.log(np.abs(np.diag(r)))))
    return log_det, float(left @ left)
