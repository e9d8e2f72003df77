"""A candidate's value where its effect is not linear in it, for the search
(search.py): an additive parameter (a dead zone) by Gauss-Newton steps from
the linear fit, a value of its own (a time constant, a conductance) by
least squares over its log on the effect tabulated and interpolated. Each
gives the value, its standard error and the effect at that value,
replayed."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from ..physics import Model
from ..physics.document import plain
from .candidates import Candidate
from .channel import Channel
from .replay import Measured

# Gauss-Newton on a candidate not linear in its parameter: at most this
# many steps, stopping when a step is below this share of its probe.
GAUSS_NEWTON_STEPS = 6
GAUSS_NEWTON_TOLERANCE = 0.01
# A candidate that is not additive is tabulated at most this far apart in
# the log of its value, then, about each channel's best value, at half that
# spacing, and interpolated between: for sensor_lag on the staircase the
# interpolant at half this spacing is off by 0.16 LSB at most where the
# effect is 245 LSB and the noise 6 LSB RMS, so the minimum it gives is
# where the exact one is, well within its interval; the value found is
# replayed. The coarse points only say where to look: the minimum is
# bracketed by the fine ones.
NONLINEAR_GRID_STEP = 1.0

Fitted = tuple[float, float, np.ndarray]


@dataclass
class Tabulated:
    """A candidate's effect per channel (rows) at log values, in order."""

    log_values: list[float]
    effects: dict[str, list[np.ndarray]]

    def add(self, log_value: float, predicted: Mapping[str, np.ndarray], base: Mapping[str, np.ndarray]) -> None:
        at = int(np.searchsorted(self.log_values, log_value))
        self.log_values.insert(at, log_value)
        for channel, rows in self.effects.items():
            rows.insert(at, predicted[channel] - base[channel])


class NonlinearFits:
    """The fits on one measured run, by replays of `predict` (the search's),
    each candidate's table kept for the run's later rounds and channels."""

    def __init__(self, measured: Measured, predict: Callable[[Model], dict[str, np.ndarray]]) -> None:
        self.measured = measured
        self.predict = predict
        self._tables: dict[tuple[str, str], Tabulated] = {}

    def fit_gauss_newton(
        self, candidate: Candidate, channel: Channel, model: Model, base: Mapping[str, np.ndarray], value: float
    ) -> Fitted:
        """Least squares of the whitened blocks over an additive parameter
        whose effect is not linear in it (a dead zone), by Gauss-Newton
        steps from the linear fit's value, each slope from replays: the
        value (within its bounds), its standard error from the slope there, and
        the effect at that value (rows)."""
        low, high = candidate.bounds
        channel_name = channel.name

        def effect(at: float) -> np.ndarray:
            return self.predict(candidate.changed(model, {channel_name: at}))[channel_name] - base[channel_name]

        for _ in range(GAUSS_NEWTON_STEPS):
            value = float(np.clip(value, low, high))
            current = effect(value)
            step = candidate.probe if value + candidate.probe <= high else -candidate.probe
            slope = (effect(value + step) - current) / step
            result = channel.fit(
                channel.blocks(slope[channel.rows])[:, None], left=channel.y - channel.blocks(current[channel.rows])
            )
            change = float(result.params[0])
            value += change
            if abs(change) < GAUSS_NEWTON_TOLERANCE * abs(candidate.probe):
                break
        value = float(np.clip(value, low, high))
        return value, float(result.bse[0]), effect(value)

    def fit_tabulated(
        self, candidate: Candidate, channel: Channel, model: Model, base: Mapping[str, np.ndarray]
    ) -> Fitted:
        """Least squares of the whitened blocks over the parameter's value
        (log scale, within its bounds): the cost on the tabulated effect,
        interpolated cubically in the log value, from the best grid value
        to the minimum between its neighbours; then the value's effect
        replayed, and its standard error from the interpolant's slope there (the
        linearised GLS)."""
        channel_name = channel.name

        def effect(value: float) -> np.ndarray:
            return self.predict(candidate.changed(model, {channel_name: value}))[channel_name] - base[channel_name]

        table = self._table(candidate, model, base)

        def cost_at(effect_blocks: np.ndarray) -> float:
            left = channel.beyond_nuisance(channel.whiten(channel.y - effect_blocks))
            return float(left @ left)

        coarse = [cost_at(channel.blocks(rows[channel.rows])) for rows in table.effects[channel_name]]
        self._refined_about(table, candidate, model, base, int(np.argmin(coarse)))
        blocks = np.array([channel.blocks(rows[channel.rows]) for rows in table.effects[channel_name]])
        interpolated = CubicSpline(table.log_values, blocks, axis=0)

        def cost(log_value: float) -> float:
            return cost_at(interpolated(log_value))

        grid = np.array(table.log_values)
        nearest = int(np.argmin([cost_at(effect_blocks) for effect_blocks in blocks]))
        bracket = (grid[max(nearest - 1, 0)], grid[min(nearest + 1, len(grid) - 1)])
        best = minimize_scalar(cost, bounds=bracket, method="bounded", options={"xatol": 1e-3})
        value = float(np.exp(best.x))
        # d effect / d value, from the interpolant's slope in the log value.
        slope = interpolated(best.x, 1) / value
        return value, float(channel.fit(slope[:, None]).bse[0]), effect(value)

    def _table(self, candidate: Candidate, model: Model, base: Mapping[str, np.ndarray]) -> Tabulated:
        """The candidate's effect on each of its channels (rows) at
        NONLINEAR_GRID_STEP-spaced log values over its search range, and at
        the values _refined_about added: one replay a value, shared by
        every channel it acts on."""
        key = (candidate.name, json.dumps(plain(model.terms), sort_keys=True))
        if key not in self._tables:
            low, high = np.log(candidate.bounds[0]), np.log(candidate.bounds[1])
            channels = [c for c in candidate.channels if c in self.measured.channels]
            table = Tabulated([], {c: [] for c in channels})
            for log_value in np.linspace(low, high, max(4, int(np.ceil((high - low) / NONLINEAR_GRID_STEP)) + 1)):
                table.add(float(log_value), self._predicted_at(candidate, model, float(log_value)), base)
            self._tables[key] = table
        return self._tables[key]

    def _predicted_at(self, candidate: Candidate, model: Model, log_value: float) -> dict[str, np.ndarray]:
        channels = [c for c in candidate.channels if c in self.measured.channels]
        return self.predict(candidate.changed(model, {channels[0]: float(np.exp(log_value))}))

    def _refined_about(
        self, table: Tabulated, candidate: Candidate, model: Model, base: Mapping[str, np.ndarray], index: int
    ) -> None:
        """The table with the points halfway to the neighbours of its
        index-th value, where it has none closer."""
        values = list(table.log_values)
        spacing = NONLINEAR_GRID_STEP / 2.0
        for neighbour in (index - 1, index + 1):
            if 0 <= neighbour < len(values) and abs(values[neighbour] - values[index]) > spacing * 1.01:
                middle = 0.5 * (values[neighbour] + values[index])
                table.add(middle, self._predicted_at(candidate, model, middle), base)
