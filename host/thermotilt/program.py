"""The chamber program as the host offers it: the settings of lib/Program's
SETPRG and lib/ChamberControl's SETCTL, the paper's values for them, and the
ranges the command line accepts. Imports nothing, so the command line can
offer these choices without loading the twin.
"""

from __future__ import annotations

# Figure 8 and section 3.2: steps of 2 degC held for one minute.
PAPER_STEP_C = 2.0
PAPER_HOLD_S = 60
# Rest with the Peltier off after a cycle (the firmware's default).
DEFAULT_REST_S = 1200
CALIBRATION_MIN_C = -10.0
CALIBRATION_MAX_C = 45.0
# An hour per step and a day of rest keep the paper's longest cycle (57
# steps) within the chamber firmware's uint32 milliseconds.
HOLD_SECONDS_RANGE = (1, 3600)
REST_SECONDS_RANGE = (0, 86400)

# SETPRG's hold_start (lib/Program): T timed, F the first step of each cycle
# waits for its setpoint, A every step does (the paper's rule, the default).
HOLD_STARTS = ("T", "F", "A")
DEFAULT_HOLD_START = "A"
# A waiting step's hold starts within this of its setpoint (lib/Program).
REACHED_BAND_C = 1.0

# lib/ChamberControl's ChamberController::kPaperProportionalGain.
PAPER_PROPORTIONAL_GAIN = 350.0
# --controller: the SETCTL a scenario sends before START; "float" sends none
# and runs the firmware's default, the paper's P law in float.
CONTROLLERS = {"float": None, "rounded-error": ("PR", PAPER_PROPORTIONAL_GAIN, 0.0)}
DEFAULT_CONTROLLER = "float"
