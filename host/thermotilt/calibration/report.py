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

from ..lsm9ds0 import tilt_deg  # noqa: E402
from .dataset import FIT_AXES, Campaign  # noqa: E402
from .fit import SurfaceFit, format_table  # noqa: E402
from .newey_west import group_bounds  # noqa: E402
from .validate import SET_NAMES, Coefficients, Validation, format_validation, range_warnings  # noqa: E402

DPI = 110
SET_COLOURS = {"W": "tab:red", "C": "tab:blue"}
FIGURE_ROWS_PER_POSITION = 2000
LEGEND_COLUMNS = 6
# Rows drawn in a run's figure, at most: a 12 h run has 432 000.
FIGURE_POINTS = 20000


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


def change_figure(validation: Validation, path: Path) -> str | None:
    """What a monitoring user reads: per axis the change of tilt from the
    installation reading against time, of the filtered reading (before) and
    of the compensated one (after), with the certificate's ±U at each row
    and the device's set switches marked; None without a change."""
    change = validation.change
    if change is None:
        return None
    series = validation.series
    hours = (series["time_s"] - series["time_s"][0]) / 3600.0
    thin = slice(None, None, max(1, len(hours) // FIGURE_POINTS))
    minute = (series["time_s"] >= change.installation.start_s) & (series["time_s"] < change.installation.end_s)
    figure, axes = plt.subplots(len(FIT_AXES), 1, figsize=(9, 3.0 * len(FIT_AXES)), sharex=True)
    for axis, plot in zip(FIT_AXES, axes):
        before = series[f"{axis} before"]
        before_deg = tilt_deg(before) - float(tilt_deg(np.array(np.median(before[minute]))))
        reach = f"{np.nanmin(before_deg):+.2f}…{np.nanmax(before_deg):+.2f}°"
        plot.plot(hours[thin], before_deg[thin], color="tab:gray", linewidth=0.8, label=f"filtered (before), {reach}")
        plot.plot(hours[thin], change.change_deg[axis][thin], color="black", linewidth=0.8, label="compensated")
        if change.u95_deg is not None:
            u95 = change.u95_deg[axis][thin]
            plot.fill_between(hours[thin], -u95, u95, color="tab:green", alpha=0.2, label="± certificate's U")
        for switch in validation.switches:
            plot.axvline((switch.time_s - series["time_s"][0]) / 3600.0, color="tab:blue", linewidth=0.5, alpha=0.5)
        low, high = np.nanpercentile(change.change_deg[axis], [0.5, 99.5])
        span = max(high - low, 0.02)
        plot.set_ylim(low - span, high + span)
        plot.set_ylabel(f"{axis}: change of tilt (°)")
        plot.legend(loc="upper right", fontsize="small")
    axes[0].set_title("Change from the installation reading (blue: the device's set switches)")
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
    change = change_figure(validation, out_dir / "change.png")
    lines = [
        "# Field validation",
        "",
        "The change of each axis's compensated reading from the installation reading, as a monitoring "
        "user reads the node; then the paper's measure (§4.3): each axis's filtered reading minus its "
        "reading at 25 °C, before and after compensation, per set the device chose (docs/calibration.md).",
        "",
        "```",
        format_validation(validation, paper, paper_table=True),
        "```",
        "",
    ]
    warnings = range_warnings(validation)
    if warnings:
        lines += ["## Range", "", *(f"- {warning}" for warning in warnings), ""]
    if change is not None:
        lines += [f"![the change of tilt from the installation reading]({change})", ""]
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
