"""The LSM9DS0 as the host sees it (datasheet; paper section 2): the raw
registers' ranges and the accelerometer's sensitivity at +-2 g, which the
twin, the firmware's processing compiled for the host and the fits share."""

import numpy as np

# OUT_X/Y/Z_L_A and _H_A: 16-bit two's complement.
ACCELERATION_RAW_RANGE = range(-32768, 32768)
# OUT_TEMP_XM: 12-bit two's complement, 8 LSB/degC.
TEMPERATURE_RAW_RANGE = range(-2048, 2048)
MG_PER_LSB = 0.061
LSB_PER_G = 1000.0 / MG_PER_LSB


def tilt_deg(acceleration_lsb: np.ndarray) -> np.ndarray:
    """The tilt about one axis from that axis's reading alone (the paper
    compensates X and Y, section 5): asin of its share of 1 g."""
    return np.degrees(np.arcsin(np.clip(acceleration_lsb / LSB_PER_G, -1.0, 1.0)))
