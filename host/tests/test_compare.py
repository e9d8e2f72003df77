"""What a fit over few positions can know of its sensor's drift when each
mounting changes the drift's slope (physics-model.md, drift_repeatability):
expected_mounting_miss_lsb against fits of simulated positions."""

import numpy as np
import pytest

from thermotilt.calibration.compare import CALIBRATED_C, GRID_POINTS, expected_mounting_miss_lsb
from thermotilt.surfaces import REFERENCE_C

SIGMA = 0.8  # LSB per degC, the default model's Y
G = 16393.0  # LSB per g (docs/run-log.md)
DRAWS = 400


def surface_terms(temperature, acceleration):
    return np.column_stack(
        [
            np.ones_like(temperature),
            temperature,
            acceleration,
            temperature**2,
            temperature * acceleration,
            acceleration**2,
        ]
    )


def simulated_miss(accelerations, rng):
    """RMS over the domain of a 2nd-order surface fitted to one draw of the
    mountings' slopes alone, relative to 25 degC, as compare measures it."""
    temperature = np.tile(np.linspace(*CALIBRATED_C, 56), len(accelerations))
    acceleration = np.repeat(accelerations, 56)
    slopes = np.repeat(rng.normal(0.0, SIGMA, len(accelerations)), 56)
    scale = np.array([1.0, 10.0, 1e4, 100.0, 1e5, 1e8])
    design = surface_terms(temperature, acceleration) / scale
    coefficients = np.linalg.lstsq(design, slopes * (temperature - REFERENCE_C), rcond=None)[0] / scale
    grid_t, grid_a = np.meshgrid(
        np.linspace(*CALIBRATED_C, GRID_POINTS), np.linspace(min(accelerations), max(accelerations), GRID_POINTS)
    )
    at = surface_terms(grid_t.ravel(), grid_a.ravel()) @ coefficients
    at_25 = surface_terms(np.full(grid_a.size, REFERENCE_C), grid_a.ravel()) @ coefficients
    return np.sqrt(np.mean((at - at_25) ** 2))


@pytest.mark.parametrize(
    "degrees",
    [
        (0, 0, 0, 0, 0, 20, -20, 40, -40),  # 0, X±20, X±40, Y±20, Y±40 seen from X
        (0, 15, -15, 30, -30, 45, -45, 0, 0),
        (-40, -40, -40, 0, 0, 0, 40, 40, 40),
    ],
)
def test_the_expected_miss_is_what_fits_of_simulated_mountings_miss(degrees):
    accelerations = [G * np.sin(np.radians(d)) for d in degrees]
    rng = np.random.default_rng(7)
    misses = np.array([simulated_miss(accelerations, rng) for _ in range(DRAWS)])
    # The mean square over 400 draws: its standard error, from the draws, bounds the check at 4 of them.
    mean_square, error = np.mean(misses**2), np.std(misses**2) / np.sqrt(DRAWS)
    expected = expected_mounting_miss_lsb(SIGMA, CALIBRATED_C, accelerations)
    assert abs(expected**2 - mean_square) < 4 * error
