"""Newey-West (HAC) covariance within panels: statsmodels' ``hac-panel``
(``cov_nw_panel`` with Bartlett weights and its "hac" small-sample
correction, t bounds on groups - 1 degrees of freedom) computed in the
frequency domain.

Written here because statsmodels' ``S_nw_panel`` stacks every group again
for each lag: with a few thousand lags over a campaign's 10^6 rows that is
minutes (the lag window comes from the residuals, ``fit.hac_lags``). The
weighted sum of every lag's autocovariance is the scores' cross-spectrum
summed under the weights' spectrum, one FFT per group: the same matrix in
a fraction of a second; host/tests/test_newey_west.py holds it to
statsmodels' to 1e-9.
"""

from __future__ import annotations

import numpy as np
from scipy import fft, stats
from statsmodels.regression.linear_model import RegressionResults
from statsmodels.stats.sandwich_covariance import weights_bartlett


def group_bounds(groups: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) of each run of equal group labels, as statsmodels reads ``groups``."""
    starts = np.flatnonzero(groups[1:] != groups[:-1]) + 1
    edges = [0, *starts.tolist(), len(groups)]
    return list(zip(edges[:-1], edges[1:]))


def panel_scores_covariance(scores: np.ndarray, groups: np.ndarray, maxlags: int) -> np.ndarray:
    """S = sum over groups of sum_{|l| <= maxlags} w_|l| G_l, where G_l =
    sum_t x[t + l] x[t]' within a group (G_-l = G_l') and w the Bartlett
    weights. Zero-padded past the group's rows and the lags, the circular
    autocovariances are the linear ones, so S is the cross-spectrum summed
    under the weights' spectrum: one FFT of the scores, no inverse."""
    weights = weights_bartlett(maxlags) if maxlags > 0 else np.array([1.0])
    k = scores.shape[1]
    total = np.zeros((k, k))
    for start, end in group_bounds(groups):
        x = scores[start:end]
        lags = min(maxlags, len(x) - 1)
        size = fft.next_fast_len(len(x) + lags + 1, real=True)
        circular = np.zeros(size)
        circular[: lags + 1] = weights[: lags + 1]
        circular[size - lags :] = weights[lags:0:-1]
        window = fft.rfft(circular).real
        # The bins between 0 and size/2 stand for their mirror images too.
        window[1 : (size + 1) // 2] *= 2.0
        spectra = fft.rfft(x, n=size, axis=0)
        cross = (spectra.real.T * window) @ spectra.real + (spectra.imag.T * window) @ spectra.imag
        total += cross / size
    return total


def hac_panel_covariance(ols: RegressionResults, groups: np.ndarray, maxlags: int) -> np.ndarray:
    """The parameters' covariance statsmodels' ``hac-panel`` gives for these
    groups (each group's rows contiguous and in time order) and lags."""
    exog = ols.model.exog
    scores = exog * ols.resid[:, None]
    inverse = ols.normalized_cov_params
    observations, parameters = scores.shape
    covariance = inverse @ panel_scores_covariance(scores, groups, maxlags) @ inverse.T
    return covariance * observations / (observations - parameters)


def hac_panel_bounds(
    ols: RegressionResults, groups: np.ndarray, covariance: np.ndarray, confidence: float
) -> np.ndarray:
    """(lower, upper) per parameter from its hac_panel_covariance: t bounds
    on groups - 1 degrees of freedom."""
    errors = np.sqrt(np.diag(covariance))
    quantile = stats.t.ppf(0.5 + confidence / 2.0, len(group_bounds(groups)) - 1)
    return np.column_stack([ols.params - quantile * errors, ols.params + quantile * errors])
