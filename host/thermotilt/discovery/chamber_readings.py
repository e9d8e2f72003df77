"""The chamber's side of a generated run (hide.py) and the frames as
discovery reads them: the inner face as its thermistor reads it (the
model's ``thermistor_lag``), each new reading with the ADC noise the twin's
readings lack, held from one chamber status frame to the next as a logger
holds them; and what a chamber effect changes in them, from the chamber's
replay with and without it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from ..physics import Chamber, Model
from ..physics.terms.lag import first_order
from .replay import (
    CHAMBER_CHANNELS,
    FIRMWARE_OUTPUTS,
    Measured,
    chamber_replay,
    chamber_rows,
    reading_offsets_c,
    settled_rows,
)

# The thermistors' ADC noise, which the twin's readings lack (simavr converts
# the divider's voltage exactly): assumed 0.5 code RMS per conversion, a
# quarter of the ATmega2560's typical absolute accuracy (datasheet, ADC
# characteristics: 2 codes, its static errors included). A reading averages
# two conversions (firmware/thermal_chamber), so sqrt(2) less, in degC at
# the reading's temperature (Chamber.celsius_per_adc_code).
ADC_NOISE_CODES = 0.5
ADC_CONVERSIONS_PER_READING = 2


def _channel_values(processed: Mapping[str, np.ndarray], frames: np.ndarray) -> dict[str, np.ndarray]:
    return {channel: processed[output][frames].astype(float) for channel, output in FIRMWARE_OUTPUTS.items()}


def thermistor_reading(time_s: np.ndarray, face_c: np.ndarray, model: Model) -> np.ndarray:
    """What the inner thermistor reads of the face through the model's
    `thermistor_lag` (each step towards the step's mean face temperature)."""
    if not model.enabled("thermistor_lag"):
        return face_c
    follow = first_order(float(model.terms["thermistor_lag"]["time_constant_s"]))
    reading = np.empty_like(face_c)
    reading[0] = face_c[0]
    for index in range(1, len(face_c)):
        target = 0.5 * (face_c[index] + face_c[index - 1])
        reading[index] = follow(reading[index - 1], target, float(time_s[index] - time_s[index - 1]))
    return reading


def _frame_rows(inputs: Measured, processed: Mapping[str, np.ndarray], frames: np.ndarray) -> tuple[np.ndarray, ...]:
    """The frames' times, the input row each falls in, and which frames
    show a new chamber status."""
    time_s = processed["grid_time_s"][frames]
    row = np.minimum(np.searchsorted(inputs.time_s, time_s, side="right") - 1, len(inputs.time_s) - 1)
    status = inputs.status[row] & (np.diff(row, prepend=-1) != 0)
    status[0] = True
    return time_s, row, status


def adc_noise_c(
    inputs: Measured, processed: Mapping[str, np.ndarray], frames: np.ndarray, model: Model, seed: int
) -> np.ndarray:
    """The thermistors' ADC noise on each new reading (ADC_NOISE_CODES), in
    degC at the reading, inner and outer (2 x new readings); its own
    generator, so the run with the effect gets the same noise."""
    _, row, status = _frame_rows(inputs, processed, frames)
    chamber = Chamber(model, float(inputs.ambient_c[0]))
    readings = np.stack([inputs.chamber_c[row][status], inputs.outer_c[row][status]])
    codes = ADC_NOISE_CODES / math.sqrt(ADC_CONVERSIONS_PER_READING)
    spans = np.vectorize(chamber.celsius_per_adc_code)(readings)
    return codes * spans * np.random.default_rng([seed, 2]).standard_normal(readings.shape)


def frames_measured(
    inputs: Measured,
    processed: Mapping[str, np.ndarray],
    frames: np.ndarray,
    model: Model,
    noise_c: np.ndarray,
    change: ChamberChange | None = None,
) -> Measured:
    """The generated frames as a Measured: the same inputs at the frame
    times, the inner face as its thermistor reads it, each new reading with
    its ADC noise (noise_c, adc_noise_c) and held from one chamber status
    frame to the next, as a logger holds them; with a chamber effect's
    change on the readings."""
    time_s, row, status = _frame_rows(inputs, processed, frames)
    new = np.flatnonzero(status)
    held = np.cumsum(status) - 1
    face_c = inputs.chamber_c if change is None else inputs.chamber_c + change.face_c
    reading_c = thermistor_reading(time_s, np.interp(time_s, inputs.time_s, face_c), model)
    outer_c = inputs.outer_c[row]
    if change is not None:
        reading_c = reading_c + change.inner_offset_c
        outer_c = outer_c + change.outer_c[row]
    reading_c = (reading_c[new] + noise_c[0])[held]
    outer_c = (outer_c[new] + noise_c[1])[held]
    values = _channel_values(processed, frames)
    values.update(inner=reading_c, outer=outer_c)
    mounting = inputs.mounting[row]
    settled = settled_rows(time_s, mounting, np.full(len(time_s), np.nan))
    used = {channel: settled.copy() for channel in values}
    used.update(inner=chamber_rows(time_s, status), outer=chamber_rows(time_s, status))
    for channel in inputs.skipped_channels:
        if channel in CHAMBER_CHANNELS:
            del values[channel], used[channel]
    return Measured(
        source="generated",
        time_s=time_s,
        chamber_c=reading_c,
        incl_x_deg=inputs.incl_x_deg[row],
        incl_y_deg=inputs.incl_y_deg[row],
        mounting=mounting,
        ambient_c=inputs.ambient_c[row],
        outer_c=outer_c,
        duty=inputs.duty[row],
        direction=inputs.direction[row],
        status=status,
        observed=values,
        used=used,
        skipped_rows=0,
        skipped_channels={c: why for c, why in inputs.skipped_channels.items() if c in CHAMBER_CHANNELS},
    )


@dataclass(frozen=True)
class ChamberChange:
    """What a chamber effect changes in a run, from the chamber's replay on
    its inputs with and without it: the inner face and the outer reading
    (at the input's rows), and the inner thermistor's reading offset."""

    face_c: np.ndarray
    outer_c: np.ndarray
    inner_offset_c: float

    @classmethod
    def of(cls, inputs: Measured, model: Model, changed: Model) -> ChamberChange:
        inner_before, outer_before = reading_offsets_c(model)
        inner_after, outer_after = reading_offsets_c(changed)
        # Both replays start from the same faces: the run with the effect
        # begins with readings shifted by the offsets' change.
        shifted = replace(
            inputs,
            chamber_c=inputs.chamber_c + (inner_after - inner_before),
            outer_c=inputs.outer_c + (outer_after - outer_before),
        )
        before, after = chamber_replay(inputs, model), chamber_replay(shifted, changed)
        return cls(
            face_c=after["face"] - before["face"],
            outer_c=after["outer"] - before["outer"],
            inner_offset_c=inner_after - inner_before,
        )
