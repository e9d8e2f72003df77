"""calibration.newey_west against statsmodels' own hac-panel, which it
computes faster (one FFT of the scores instead of a pass per lag)."""

import numpy as np
import pytest
import statsmodels.api as sm

from thermotilt.calibration.newey_west import hac_panel_bounds, hac_panel_covariance


def autocorrelated_panel(seed: int, lengths: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of several groups with AR(1) errors, as a filtered log's residuals are."""
    rng = np.random.default_rng(seed)
    rows = sum(lengths)
    exog = np.column_stack([np.ones(rows), rng.normal(size=rows), rng.uniform(-1, 1, size=rows) ** 2])
    errors = np.zeros(rows)
    for index in range(1, rows):
        errors[index] = 0.95 * errors[index - 1] + rng.normal()
    groups = np.repeat(np.arange(len(lengths)), lengths)
    return exog @ np.array([1.0, -2.0, 0.5]) + errors, exog, groups


@pytest.mark.parametrize("maxlags", [0, 1, 7, 60, 150])
@pytest.mark.parametrize("lengths", [(200, 200, 200), (90, 300, 31, 120)])
def test_the_covariance_and_bounds_are_statsmodels(maxlags, lengths):
    endog, exog, groups = autocorrelated_panel(3, lengths)
    ols = sm.OLS(endog, exog).fit(method="qr")
    reference = ols.get_robustcov_results(cov_type="hac-panel", groups=groups, maxlags=maxlags)
    # Lags beyond a group's length: statsmodels leaves that group out of those lags, as here.
    covariance = hac_panel_covariance(ols, groups, maxlags)
    np.testing.assert_allclose(covariance, reference.cov_params(), rtol=1e-9)
    np.testing.assert_allclose(hac_panel_bounds(ols, groups, covariance, 0.95), reference.conf_int(0.05), rtol=1e-9)
