"""Calibration: a campaign's run logs turned into drift surfaces with their
statistics (docs/calibration.md)."""
