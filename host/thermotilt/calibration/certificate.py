"""A calibration certificate per sensor: what the compensated tilt is good
for, in degrees, over the domain the campaign covered (GUM vocabulary,
JCGM 100:2008).

The measurand is the tilt about X or Y from that axis's compensated reading
(``validate.tilt_deg``, the paper's advice to use X and Y, section 5), its
error the tilt less the tilt of the position's 25 degC reading — what
``validate`` reports for a field run as ``tilt_error_p95_deg``.

Two components, both Type A from the campaign:
- the scatter the surfaces leave: the RMS of every calibration row's tilt
  error after compensation, pooled over sets and axes;
- the surfaces' own uncertainty: each row's prediction variance from the
  coefficients' Newey-West covariance (``fit.SurfaceFit.hac_covariance``),
  averaged over the rows.
The rows of a filtered 10 Hz log are strongly autocorrelated, so the
scatter rests on far fewer independent values than rows: its effective
count is the errors' variance over the Newey-West variance of their mean
within each calibration point (the same lag rule as the fit). The degrees
of freedom of the combined uncertainty follow Welch-Satterthwaite (GUM
G.4.1), the coverage factor is Student's t at 95 %, and the expanded
uncertainty ``tilt_u95_deg`` = k u_c.
"""

from __future__ import annotations

import base64
import html
import io
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import stats
from statsmodels.regression.linear_model import OLS

from ..lsm9ds0 import LSB_PER_G, MG_PER_LSB
from ..surfaces import SETS
from .dataset import Campaign
from .fit import SurfaceFit, design, hac_lags
from .newey_west import hac_panel_covariance
from .validate import SET_NAMES, tilt_deg

COVERAGE_PROBABILITY = 0.95
CERTIFICATE_JSON = "certificate.json"
CERTIFICATE_HTML = "certificate.html"
# Rows beyond this many per calibration point are thinned in the figure only.
FIGURE_ROWS_PER_POINT = 400


@dataclass(frozen=True)
class PointError:
    """The error after compensation at one calibration point: a position's
    rows of one set, on one axis."""

    position: str
    set_name: str
    axis: str
    rows: int
    temperature_range_c: tuple[float, float]
    rms_lsb: float
    rms_mg: float
    tilt_p95_deg: float


@dataclass(frozen=True)
class Uncertainty:
    scatter_deg: float
    surfaces_deg: float
    standard_deg: float
    rows: int
    effective_rows: float
    degrees_of_freedom: float
    coverage_factor: float
    expanded_deg: float


@dataclass(frozen=True)
class _Errors:
    """Every calibration row's tilt error after compensation, pooled."""

    tilt_deg: np.ndarray
    surface_variance_deg2: np.ndarray
    temperature_c: np.ndarray
    point: np.ndarray  # index into points
    points: list[PointError]


def _errors(campaign: Campaign, fits: list[SurfaceFit]) -> _Errors:
    tilts, variances, temperatures, labels, points = [], [], [], [], []
    for fit in fits:
        data = campaign.sets[fit.set_name]
        temperature, acceleration = data.temperature_c, data.acceleration[fit.axis]
        left = data.residual[fit.axis] - fit.surface.evaluate(temperature, acceleration)
        at_25 = acceleration - data.residual[fit.axis]
        tilt = tilt_deg(at_25 + left) - tilt_deg(at_25)
        rows = design(temperature, acceleration)
        variance_lsb2 = np.einsum("ij,jk,ik->i", rows, fit.hac_covariance, rows)
        # d(asin(a/g))/da, in degrees per LSB, at the row's reading.
        slope = np.degrees(1.0 / np.sqrt(np.maximum(LSB_PER_G**2 - (at_25 + left) ** 2, 1.0)))
        for position in np.unique(data.position).tolist():
            mine = data.position == position
            rms_lsb = float(np.sqrt(np.mean(left[mine] ** 2)))
            labels.append(np.full(int(mine.sum()), len(points)))
            points.append(
                PointError(
                    campaign.positions[position],
                    fit.set_name,
                    fit.axis,
                    int(mine.sum()),
                    (float(temperature[mine].min()), float(temperature[mine].max())),
                    rms_lsb,
                    rms_lsb * MG_PER_LSB,
                    float(np.percentile(np.abs(tilt[mine]), 95.0)),
                )
            )
            tilts.append(tilt[mine])
            variances.append(variance_lsb2[mine] * slope[mine] ** 2)
            temperatures.append(temperature[mine])
    return _Errors(
        np.concatenate(tilts), np.concatenate(variances), np.concatenate(temperatures), np.concatenate(labels), points
    )


def effective_count(errors: np.ndarray, groups: np.ndarray) -> float:
    """How many independent values the errors are worth for their mean:
    their variance over the Newey-West variance of the mean within each
    group (contiguous, in time order), at most their count."""
    ols = OLS(errors, np.ones((len(errors), 1))).fit()
    shortest = int(np.min(np.unique(groups, return_counts=True)[1]))
    lags = min(hac_lags(ols.resid), max(1, shortest - 1))
    variance_of_mean = float(hac_panel_covariance(ols, groups, lags)[0, 0])
    spread = float(np.var(errors, ddof=1))
    return float(len(errors)) if variance_of_mean <= 0.0 else min(float(len(errors)), spread / variance_of_mean)


def uncertainty(errors: _Errors, positions: int) -> Uncertainty:
    scatter = float(np.sqrt(np.mean(errors.tilt_deg**2)))
    surfaces = float(np.sqrt(np.mean(errors.surface_variance_deg2)))
    standard = float(np.hypot(scatter, surfaces))
    effective = effective_count(errors.tilt_deg, errors.point)
    # Welch-Satterthwaite: the scatter on its effective rows, the surfaces on
    # the positions their Newey-West bounds rest on (fit.hac_panel_bounds).
    freedoms = standard**4 / (scatter**4 / max(effective - 1.0, 1.0) + surfaces**4 / max(positions - 1, 1))
    factor = float(stats.t.ppf(0.5 + COVERAGE_PROBABILITY / 2.0, freedoms))
    return Uncertainty(
        scatter, surfaces, standard, len(errors.tilt_deg), effective, freedoms, factor, factor * standard
    )


def _provenance(campaign_dir: Path) -> dict[str, object]:
    """What campaign.json says of the run (firmware, when), if there is one."""
    path = campaign_dir / "campaign.json"
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {"campaign_file": None, "created_utc": None, "firmware": []}
    firmware = sorted(
        {
            f"{board}: {version}"
            for position in document.get("positions", [])
            for board, version in (position.get("firmware") or {}).items()
        }
    )
    return {"campaign_file": str(path), "created_utc": document.get("created_utc"), "firmware": firmware}


def certify(
    campaign: Campaign, fits: list[SurfaceFit], campaign_dir: Path, sensor_id: str = ""
) -> tuple[dict, _Errors]:
    """certificate.json's document, and the rows' errors its figure shows."""
    errors = _errors(campaign, fits)
    result = uncertainty(errors, len(campaign.positions))
    domain = {
        "temperature_c": {
            SET_NAMES[set_name]: [
                min(f.temperature_range_c[0] for f in fits if f.set_name == set_name),
                max(f.temperature_range_c[1] for f in fits if f.set_name == set_name),
            ]
            for set_name in SETS
            if any(f.set_name == set_name for f in fits)
        },
        "tilt_deg": {
            axis: [
                float(tilt_deg(np.array(min(f.acceleration_range_lsb[0] for f in fits if f.axis == axis)))),
                float(tilt_deg(np.array(max(f.acceleration_range_lsb[1] for f in fits if f.axis == axis)))),
            ]
            for axis in dict.fromkeys(f.axis for f in fits)
        },
    }
    return {
        "sensor_id": sensor_id,
        "issued_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "campaign": str(campaign_dir),
        **_provenance(campaign_dir),
        "domain": domain,
        "tilt_u95_deg": result.expanded_deg,
        "uncertainty": asdict(result),
        "method": (
            "Type A (JCGM 100:2008): tilt about X and Y from each axis's compensated reading, error about "
            "the position's 25 degC reading; u_c combines the RMS error of the calibration rows and the "
            "fitted surfaces' Newey-West prediction uncertainty; the rows' autocorrelation is accounted for "
            "by their effective count (Newey-West variance of the mean within each calibration point); "
            "degrees of freedom by Welch-Satterthwaite; U = k u_c with Student's k at 95 %"
        ),
        "points": [asdict(point) for point in errors.points],
    }, errors


def _figure(document: dict, errors: _Errors) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    expanded = document["tilt_u95_deg"]
    figure, (by_point, by_temperature) = plt.subplots(1, 2, figsize=(11, 4.0), gridspec_kw={"width_ratios": [3, 2]})
    colours = {("W", "X"): "tab:red", ("C", "X"): "tab:blue", ("W", "Y"): "tab:orange", ("C", "Y"): "tab:cyan"}
    positions = list(dict.fromkeys(point["position"] for point in document["points"]))
    for key, colour in colours.items():
        mine = [p for p in document["points"] if (p["set_name"], p["axis"]) == key]
        if mine:
            by_point.plot(
                [positions.index(p["position"]) for p in mine],
                [p["tilt_p95_deg"] for p in mine],
                "o",
                color=colour,
                markersize=4,
                label=f"{SET_NAMES[key[0]]} {key[1]}",
            )
    by_point.axhline(expanded, color="black", linestyle="--", linewidth=1, label="U (95 %)")
    by_point.set_xticks(range(len(positions)), [p.split(" (")[-1].rstrip(")") for p in positions], rotation=90)
    by_point.tick_params(axis="x", labelsize=6)
    by_point.set_ylabel("95th percentile |tilt error| (°)")
    by_point.set_title("Error after compensation at each calibration point")
    by_point.legend(fontsize=7, ncol=5, loc="upper left")
    thin = np.zeros(len(errors.tilt_deg), dtype=bool)
    for point in np.unique(errors.point):
        rows = np.flatnonzero(errors.point == point)
        thin[rows[:: max(1, len(rows) // FIGURE_ROWS_PER_POINT)]] = True
    by_temperature.plot(errors.temperature_c[thin], errors.tilt_deg[thin], ".", markersize=1, color="tab:gray")
    by_temperature.axhspan(-expanded, expanded, color="tab:green", alpha=0.15, label="±U")
    by_temperature.set_xlabel("IMU temperature (°C)")
    by_temperature.set_ylabel("tilt error (°)")
    by_temperature.set_title("Every calibration row")
    by_temperature.legend(fontsize=7, loc="upper left")
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    plt.close(figure)
    return buffer.getvalue()


def _html(document: dict, png: bytes) -> str:
    result = document["uncertainty"]

    def row(*cells: object) -> str:
        return "<tr>" + "".join(f"<td>{html.escape(str(cell))}</td>" for cell in cells) + "</tr>"

    domain = document["domain"]
    summary = [
        ("Sensor ID", document["sensor_id"] or "(none assigned)"),
        ("Firmware", "; ".join(document["firmware"]) or "(not recorded)"),
        ("Campaign", document["campaign"]),
        ("Campaign started", document["created_utc"] or "(not recorded)"),
        ("Issued", document["issued_utc"]),
        *(
            (f"Temperature, {name}", "{:.1f} … {:.1f} °C".format(*span))
            for name, span in domain["temperature_c"].items()
        ),
        *((f"Tilt about {axis}", "{:+.1f} … {:+.1f}°".format(*span)) for axis, span in domain["tilt_deg"].items()),
    ]
    points = [
        row(
            p["position"],
            SET_NAMES[p["set_name"]],
            p["axis"],
            p["rows"],
            "{:.1f} … {:.1f}".format(*p["temperature_range_c"]),
            f"{p['rms_lsb']:.1f}",
            f"{p['rms_mg']:.2f}",
            f"{p['tilt_p95_deg']:.4f}",
        )
        for p in document["points"]
    ]
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Calibration certificate {html.escape(document["sensor_id"])}</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 8px;font-size:90%}}.big{{font-size:140%}}</style></head><body>
<h1>Thermal-drift calibration certificate</h1>
<table>{"".join(row(name, value) for name, value in summary)}</table>
<p class="big">Expanded uncertainty of compensated tilt over this domain:
<b>U = {document["tilt_u95_deg"]:.4f}°</b> (k = {result["coverage_factor"]:.2f}, coverage probability 95 %)</p>
<p>u_c = {result["standard_deg"]:.4f}°: the calibration rows' scatter {result["scatter_deg"]:.4f}° and the
fitted surfaces' {result["surfaces_deg"]:.4f}°; {result["rows"]} rows worth {result["effective_rows"]:.0f}
independent values, {result["degrees_of_freedom"]:.0f} degrees of freedom.</p>
<p><small>{html.escape(document["method"])}.</small></p>
<img src="data:image/png;base64,{base64.b64encode(png).decode()}" alt="error after compensation" width="100%">
<h2>Error after compensation at every calibration point</h2>
<table><tr><th>position</th><th>set</th><th>axis</th><th>rows</th><th>°C</th><th>RMS LSB</th><th>RMS mg</th>
<th>p95 |tilt error| °</th></tr>{"".join(points)}</table>
</body></html>
"""


def write_certificate(out_dir: Path, document: dict, errors: _Errors) -> tuple[Path, Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    json_path, html_path = out_dir / CERTIFICATE_JSON, out_dir / CERTIFICATE_HTML
    json_path.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    html_path.write_text(_html(document, _figure(document, errors)), encoding="utf-8")
    return json_path, html_path
