"""What the firmware tests share: the thermistor divider and frame picking."""

import math


def divider_millivolts(celsius: float) -> float:
    """The thermistor input for a temperature: beta equation, 100 kOhm NTC
    (beta 3950 K) to ground below a 100 kOhm reference resistor from 5 V."""
    ntc = 100e3 * math.exp(3950.0 * (1.0 / (celsius + 273.15) - 1.0 / 298.15))
    return 5000.0 * ntc / (ntc + 100e3)


def of_type(frames, frame_type):
    return [frame for frame in frames if frame.type == frame_type]
