"""ThermoTilt host tools: serial protocol, coefficients, calibration workflows."""

__version__ = "0.1.0"
