"""report.md files with PNG figures for ``fit`` and ``validate``: what a
user would rather look at than read — the paper's Figure 10 (acceleration
against temperature per inclination), Figures 12-13 (the fitted surfaces
with their data), the residuals, and Figure 16 (a field run before and after
compensation)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from .dataset import FIT_AXES, Campaign  # noqa: E402
from .fit import SurfaceFit, format_table  # noqa: E402
from .newey_west import group_bounds  # noqa: E402
from .validate import SET_NAMES, Coefficients, Validation, format_validation, range_warnings  # noqa: E402

DPI = 110
SET_COLOURS = {"W": "tab:red", "C": "tab:blue"}
FIGURE_ROWS_PER_POSITION = 2000
LEGEND_COLUMNS = 6


def _save(figure: plt.Figure, path: Path) -> str:
    figure.tight_layout()
    figure.savefig(path, dpi=DPI)
    plt.close(figure)
    return path.name


def validation_figure(validation: Validation, path: Path) -> str:
    """Figure 16's layout: temperature, then per axis the filtered reading
    before and after compensation, against time."""
    series = validation.series
    hours = (series["time_s"] - series["time_s"][0]) / 3600.0
    figure, axes = plt.subplots(1 + len(FIT_AXES), 1, figsize=(8, 2.6 * (1 + len(FIT_AXES))), sharex=True)
    axes[0].plot(hours, series["temperature_c"], color="tab:red", linewidth=1)
    axes[0].set_ylabel("IMU temperature (°C)")
    for axis, plot in zip(FIT_AXES, axes[1:]):
        plot.plot(hours, series[f"{axis} before"], color="tab:gray", linewidth=1, label="filtered (before)")
        plot.plot(hours, series[f"{axis} after"], color="black", linewidth=1, label="compensated (after)")
        plot.set_ylabel(f"{axis} (LSB)")
        plot.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("time (h)")
    return _save(figure, path)


def write_validation_report(
    out_dir: Path,
    validation: Validation,
    coefficients: Coefficients | None,
    paper: dict[tuple[str, str], tuple[float, float]] | None,
) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    figure = validation_figure(validation, out_dir / "field.png")
    lines = [
        "# Field validation",
        "",
        "RMS of each axis's filtered reading minus its reading at 25 °C, before and after "
        "compensation, per set the device chose (the paper's §4.3; docs/calibration.md).",
        "",
        "```",
        format_validation(validation, paper),
        "```",
        "",
    ]
    warnings = range_warnings(validation)
    if warnings:
        lines += ["## Range", "", *(f"- {warning}" for warning in warnings), ""]
    lines += [f"![before and after compensation]({figure})", ""]
    report = out_dir / "report.md"
    report.write_text("\n".join(lines))
    return report


def drift_figure(campaign: Campaign, path: Path) -> str:
    """Figure 10: each axis's residual (reading minus its 25 °C reading)
    against temperature, one colour per tilt position, both sets."""
    legend_rows = -(-len(campaign.positions) // LEGEND_COLUMNS)
    figure, axes = plt.subplots(1, len(FIT_AXES), figsize=(6 * len(FIT_AXES), 4.6 + 0.17 * legend_rows), squeeze=False)
    colours = plt.get_cmap("viridis")(np.linspace(0, 1, max(1, len(campaign.positions))))
    for axis, plot in zip(FIT_AXES, axes[0]):
        for data in campaign.sets.values():
            for start, end in group_bounds(data.position):
                # A position's shape shows in a few thousand of its rows.
                rows = slice(start, end, max(1, (end - start) // FIGURE_ROWS_PER_POSITION))
                plot.plot(
                    data.temperature_c[rows],
                    data.residual[axis][rows],
                    ".",
                    markersize=1,
                    color=colours[data.position[start]],
                )
        for index, position in enumerate(campaign.positions):
            # A campaign's positions are named "folder (x .. deg, y .. deg)"; the folder is the label.
            plot.plot([], [], "o", color=colours[index], label=position.split(" (")[0])
        # Below the plot: "best" would search every point for a free corner.
        plot.legend(
            fontsize="x-small", ncol=LEGEND_COLUMNS, markerscale=0.6, loc="upper center", bbox_to_anchor=(0.5, -0.16)
        )
        plot.set_xlabel("IMU temperature (°C)")
        plot.set_ylabel(f"{axis}: reading − reading at 25 °C (LSB)")
        plot.set_title(f"{axis} axis, {len(campaign.positions)} positions")
    return _save(figure, path)


def surface_figure(fits: list[SurfaceFit], campaign: Campaign, path: Path) -> str:
    """Figures 12-13: each fitted surface over its data, and the residuals."""
    figure = plt.figure(figsize=(11, 4.2 * len(fits)))
    for row, fit in enumerate(fits):
        data = campaign.sets[fit.set_name]
        temperature, acceleration = data.temperature_c, data.acceleration[fit.axis]
        residual = data.residual[fit.axis]
        step = max(1, len(temperature) // 4000)
        grid_t, grid_a = np.meshgrid(
            np.linspace(*fit.temperature_range_c, 30), np.linspace(*fit.acceleration_range_lsb, 30)
        )
        plot = figure.add_subplot(len(fits), 2, 2 * row + 1, projection="3d")
        plot.plot_surface(
            grid_t, grid_a, fit.surface.evaluate(grid_t, grid_a), alpha=0.45, color=SET_COLOURS[fit.set_name]
        )
        plot.scatter(temperature[::step], acceleration[::step], residual[::step], s=1, color="black")
        plot.set_xlabel("T (°C)")
        plot.set_ylabel("a (LSB)")
        plot.set_zlabel("residual (LSB)")
        plot.set_title(f"{fit.axis} {SET_NAMES[fit.set_name]}: RMSE {fit.rmse:.1f} LSB")
        misfit = figure.add_subplot(len(fits), 2, 2 * row + 2)
        predicted = fit.surface.evaluate(temperature, acceleration)
        misfit.plot(
            temperature[::step], (residual - predicted)[::step], ".", markersize=1, color=SET_COLOURS[fit.set_name]
        )
        misfit.axhline(0.0, color="black", linewidth=0.8)
        misfit.set_xlabel("IMU temperature (°C)")
        misfit.set_ylabel("data − surface (LSB)")
        misfit.set_title(f"{fit.axis} {SET_NAMES[fit.set_name]}: what the surface leaves")
    return _save(figure, path)


def write_fit_report(out_dir: Path, fits: list[SurfaceFit], campaign: Campaign, families: str | None = None) -> Path:
    drift = drift_figure(campaign, out_dir / "drift.png")
    surfaces = surface_figure(fits, campaign, out_dir / "surfaces.png")
    lines = [
        "# Calibration fit",
        "",
        f"{len(campaign.positions)} positions, {sum(fit.points for fit in fits)} points "
        "(docs/calibration.md says which rows and how).",
        "",
        "```",
        format_table(fits),
        "```",
        "",
        "Bounds: Newey–West (HAC) 95 % within each position; coefficients.json also has the OLS "
        "bounds, which ignore the rows' autocorrelation.",
        "",
        *(["## Model families", "", "```", families, "```", ""] if families else []),
        f"![residuals against temperature per position (the paper's Figure 10)]({drift})",
        "",
        f"![fitted surfaces with their data and what they leave (Figures 12–13)]({surfaces})",
        "",
    ]
    report = out_dir / "report.md"
    report.write_text("\n".join(lines))
    return report
