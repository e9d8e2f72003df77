"""The certificate's tables as rows of text, one layout for the HTML page
and the PDF: its fields, the U table per axis, a band's budget and the
results at the calibration points."""

from __future__ import annotations

from ...surfaces import SET_NAMES
from .budget import two_significant_text


def _degrees(value: float | None, digits: int = 4) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def field_rows(document: dict) -> list[list[str]]:
    """The certificate's fields (ISO/IEC 17025 7.8.2.1, 7.8.4.1), one per row."""
    item, procedure, program = document["item"], document["procedure"], document["chamber_program"]
    dates, domain, conversion = document["calibration_dates"], document["domain"], document["conversion"]
    tilts = "; ".join(
        f"{axis} {low:+g} to {high:+g}° (±{domain['tilt_allowance_deg'][axis]:g}° allowance)"
        for axis, (low, high) in domain["tilt_deg"].items()
    )
    zeros = ", ".join(f"{axis} {value:.1f} LSB" for axis, value in document["zero_reading_lsb"].items())
    return [
        ["Certificate number", document["certificate_number"]],
        ["Laboratory", f"{document['laboratory']['name']}; {document['laboratory']['address']}"],
        ["Customer", f"{document['customer']['name']}; {document['customer']['address']}"],
        ["Item", f"{item['model']}, sensor ID {item['sensor_id']}: {item['description']}"],
        ["Item firmware", "; ".join(item["firmware"]) or "not recorded"],
        ["Condition of the item", item["condition"]],
        ["Procedure", f"{procedure['id']}, software {procedure['software']}: {procedure['description']}"],
        ["Calibration dates", f"{dates['started_utc'] or 'not recorded'} to {dates['ended_utc'] or 'not recorded'}"],
        ["Date of issue", document["issue_date"]],
        ["Chamber program (environment)", program["description"]],
        ["Calibration positions", str(document["positions"])],
        ["Tilt reference, traceability", document["references"]["tilt"]],
        ["Temperature reference, traceability", document["references"]["temperature"]],
        ["Coefficients (coefficients.bin) sha256", document["coefficients_sha256"]],
        [
            "Domain",
            f"IMU temperature {domain['temperature_c'][0]:.1f} to {domain['temperature_c'][1]:.1f} °C; nominal tilt {tilts}",
        ],
        ["Conversion formula", conversion["formula"]],
        ["Zero reading", f"{zeros} ({conversion['zero_reading_note']})"],
    ]


def u_table_title(axis: str, table: dict, tilt_index: int) -> str:
    """The heading of one tilt band's U table: the axis, the band, its positions and k."""
    low, high = table["tilt_bands_deg"][tilt_index]
    factors = [
        k
        for installation in table["coverage_factor"]
        for reading in installation
        if (k := reading[tilt_index]) is not None
    ]
    positions = max(reading[tilt_index] for installation in table["positions"] for reading in installation)
    k_range = f"k {min(factors):.2f} to {max(factors):.2f}" if factors else "no cell evaluated"
    return f"{axis} axis, |tilt| {low:g}-{high:g}° ({positions} positions; {k_range})"


def u_table_rows(table: dict, tilt_index: int) -> list[list[str]]:
    """U (°) of one tilt band: per reading temperature band (rows) and installation band (columns)."""
    bands = table["temperature_bands_c"]
    rows = [["reading °C \\ installation °C"] + [f"{low:.1f} to {high:.1f}" for low, high in bands]]
    for i, (low, high) in enumerate(bands):
        values = [table["u95_deg"][j][i][tilt_index] for j in range(len(bands))]
        rows.append([f"{low:.1f} to {high:.1f}"] + ["–" if v is None else two_significant_text(v) for v in values])
    return rows


def budget_rows(budget: dict) -> list[list[str]]:
    """A band's budget (EA-4/02 M): each component, then u_c, nu_eff, k and U."""
    rows = [["component", "type", "value", "distribution", "divisor", "sensitivity (°/unit)", "u_i (°)", "ν", "source"]]
    for c in budget["components"]:
        rows.append(
            [
                c["name"],
                c["kind"],
                f"{c['value']:.4g} {c['unit']}",
                c["distribution"],
                f"{c['divisor']:.3g}",
                f"{c['sensitivity']:.3g}",
                f"{c['contribution_deg']:.4f}" + ("" if c["added"] else " (not added)"),
                "∞" if c["degrees_of_freedom"] is None else f"{c['degrees_of_freedom']:.0f}",
                c["source"],
            ]
        )
    dof = budget["effective_dof"]
    rows += [
        [
            "combined standard uncertainty u_c",
            "",
            "",
            "",
            "",
            "",
            f"{budget['standard_deg']:.4f}",
            "",
            "root sum of squares",
        ],
        [
            "effective degrees of freedom ν_eff",
            "",
            "",
            "",
            "",
            "",
            "",
            "∞" if dof is None else f"{dof:.1f}",
            "Welch-Satterthwaite, GUM G.4.1",
        ],
        [
            "coverage factor k (p = 95 %)",
            "",
            "",
            "",
            "",
            "",
            f"{budget['coverage_factor']:.2f}",
            "",
            "Student's t, GUM G.3",
        ],
        [
            "expanded uncertainty U = k u_c",
            "",
            "",
            "",
            "",
            "",
            two_significant_text(budget["expanded_deg"]),
            "",
            "two significant digits, rounded up",
        ],
    ]
    return rows


def point_rows(document: dict) -> list[list[str]]:
    """Per calibration point: nominal angle, as found, as left, out of sample, U."""
    rows = [
        [
            "position",
            "axis",
            "set",
            "nominal angle (°)",
            "IMU °C",
            "as found p95 |error| (°)",
            "as left p95 |error| (°)",
            "as left RMS (mg)",
            "out of sample p95 (°)",
            "U there, largest (°)",
        ]
    ]
    for p in document["points"]:
        rows.append(
            [
                p["position"].split(" (")[0],
                p["axis"],
                SET_NAMES[p["set_name"]],
                f"{p['nominal_deg']:+g}",
                "{:.1f} to {:.1f}".format(*p["temperature_range_c"]),
                _degrees(p["as_found_p95_deg"], 3),
                _degrees(p["as_left_p95_deg"]),
                f"{p['as_left_rms_mg']:.3f}",
                _degrees(p["out_of_sample_p95_deg"]) + ("" if p["out_of_sample"] else " (in sample)"),
                "n/a" if p["u95_deg"] is None else two_significant_text(p["u95_deg"]),
            ]
        )
    return rows
