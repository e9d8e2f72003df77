"""What `validate` asks of a certificate: the U of a run's rows' change from
its installation reading, by the band of the installation's IMU
temperature, the row's and its nominal tilt, NaN outside its domain
(calibration/certificate/domain.py)."""

from __future__ import annotations

import numpy as np
import pytest

from thermotilt.calibration.certificate import in_domain, u95_at
from thermotilt.calibration.certificate.domain import nominal_tilt_deg, temperature_bands
from thermotilt.lsm9ds0 import LSB_PER_G

ZERO_X = -1823.0
BASE = [[0.05, 0.09], [0.02, 0.04], [0.03, 0.07]]


def document() -> dict:
    return {
        "zero_reading_lsb": {"X": ZERO_X},
        "domain": {"temperature_c": [-8.0, 43.0], "tilt_deg": {"X": [-45.0, 45.0]}, "tilt_allowance_deg": {"X": 0.5}},
        "uncertainty_table": {
            "X": {
                "temperature_bands_c": [[-8.0, 0.0], [0.0, 20.0], [20.0, 43.0]],
                "tilt_bands_deg": [[0.0, 15.0], [15.0, 45.0]],
                # [installation][reading][tilt]: installed in the reading's band, BASE; 0.1 more a band apart.
                "u95_deg": [
                    [[round(u + 0.1 * abs(early - late), 2) for u in row] for late, row in enumerate(BASE)]
                    for early in range(3)
                ],
            }
        },
    }


def reading(tilt_deg: float) -> float:
    return ZERO_X + LSB_PER_G * np.sin(np.radians(tilt_deg))


def test_u95_at_reads_the_band_of_each_row_and_is_nan_outside_the_domain():
    temperatures = np.array([-5.0, 10.0, 10.0, 25.0, 43.0, -8.5, 44.0, 25.0, 25.0, 25.0])
    tilts = [10.0, -10.0, 15.0, 15.01, -45.3, 0.0, 0.0, 46.0, 44.0, np.nan]
    compensated = np.array([reading(t) for t in tilts])
    expected = [0.25, 0.12, 0.12, 0.07, 0.07, np.nan, np.nan, np.nan, 0.07, np.nan]
    u95 = u95_at(document(), "X", temperatures, compensated, 25.0)
    np.testing.assert_allclose(u95, expected)
    assert in_domain(document(), "X", temperatures, compensated).tolist() == [not np.isnan(e) for e in expected]
    np.testing.assert_allclose(u95_at(document(), "X", temperatures[:3], compensated[:3], -5.0), [0.05, 0.12, 0.12])


def test_no_change_has_a_u95_from_an_installation_outside_the_domain():
    assert np.isnan(u95_at(document(), "X", np.array([10.0, 25.0]), np.array([reading(0.0)] * 2), 43.5)).all()


def test_a_cell_no_installation_band_states_is_outside_the_domain():
    certificate = document()
    for installation in certificate["uncertainty_table"]["X"]["u95_deg"]:
        installation[0][1] = None
    rows = np.array([-5.0, -5.0]), np.array([reading(30.0), reading(5.0)])
    assert in_domain(certificate, "X", *rows).tolist() == [False, True]


def test_an_axis_without_a_table_has_no_u95_anywhere():
    assert np.isnan(u95_at(document(), "Y", np.array([25.0]), np.array([0.0]), 25.0)).all()
    assert not in_domain(document(), "Y", np.array([25.0]), np.array([0.0])).any()


def test_the_zero_reading_turns_a_compensated_reading_into_nominal_tilt():
    assert nominal_tilt_deg(np.array([reading(30.0)]), ZERO_X)[0] == pytest.approx(30.0)


def test_temperature_bands_are_five_degrees_on_multiples_of_five_cut_at_the_domain():
    assert temperature_bands(-8.2, 43.1)[:2] == [(-8.2, -5.0), (-5.0, 0.0)]
    assert temperature_bands(-8.2, 43.1)[-1] == (40.0, 43.1)
    assert len(temperature_bands(-10.0, 45.0)) == 11
