"""The certificate as a reader gets it: a figure of U against IMU
temperature per tilt band beside the calibration points' errors
(matplotlib PNG), an HTML page and a PDF (ReportLab) carrying the
certificate's number on every page, the U table, the budget, the points
and the figure."""

from __future__ import annotations

import base64
import html
import io

from .budget import two_significant_text
from .domain import installation_band
from .errors import AxisErrors
from .points import REFERENCE_C
from .tables import budget_rows, field_rows, point_rows, u_table_rows, u_table_title

BAND_COLOURS = ("tab:green", "tab:orange", "tab:red")
# The budget's columns on a landscape A4 page, the source widest.
BUDGET_WIDTHS_MM = (38, 10, 24, 20, 14, 20, 20, 10, 111)


def figure_png(document: dict, errors: dict[str, AxisErrors]) -> bytes:
    """Per axis: U (95 %) against the reading's temperature, per tilt band a
    step line for an installation at the points' reference temperature
    (solid) and the largest over installation bands (dashed), and each
    calibration point's 95th percentile of |error| per band, as left (dots)
    and out of sample (crosses), coloured by its tilt band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes_names = list(document["uncertainty_table"])
    figure, panels = plt.subplots(1, len(axes_names), figsize=(5.5 * len(axes_names), 4.0), squeeze=False)
    for panel, axis in zip(panels[0], axes_names):
        table = document["uncertainty_table"][axis]
        at_reference = installation_band(document, axis, REFERENCE_C)
        for k, band in enumerate(table["tilt_bands_deg"]):
            colour = BAND_COLOURS[k % len(BAND_COLOURS)]
            for i, t_band in enumerate(table["temperature_bands_c"]):
                values = [installation[i][k] for installation in table["u95_deg"] if installation[i][k] is not None]
                if at_reference >= 0 and (value := table["u95_deg"][at_reference][i][k]) is not None:
                    label = f"U, |tilt| {band[0]:g}-{band[1]:g}°, installed at {REFERENCE_C:g} °C" if i == 0 else None
                    panel.plot(t_band, [value, value], color=colour, linewidth=2, label=label)
                if values:
                    label = f"largest over installations, |tilt| {band[0]:g}-{band[1]:g}°" if i == 0 else None
                    panel.plot(t_band, [max(values)] * 2, color=colour, linewidth=1, linestyle="--", label=label)
            for point in document["points"]:
                if point["axis"] != axis or not band[0] <= abs(point["nominal_deg"]) <= band[1]:
                    continue
                for check in point["bands"]:
                    middle = sum(check["temperature_band_c"]) / 2.0
                    if check["as_left_p95_deg"] is not None:
                        panel.plot(middle, check["as_left_p95_deg"], ".", color=colour, markersize=4)
                    if check["out_of_sample_p95_deg"] is not None:
                        panel.plot(middle + 0.6, check["out_of_sample_p95_deg"], "x", color=colour, markersize=4)
        panel.set_xlabel("reading's IMU temperature (°C)")
        panel.set_ylabel("tilt change error (°)")
        panel.set_title(f"{axis}: U (lines); points' p95 as left (·), out of sample (×)", fontsize=9)
        panel.set_ylim(bottom=0.0)
        panel.legend(fontsize=6, loc="upper center")
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    plt.close(figure)
    return buffer.getvalue()


def _html_table(rows: list[list[str]], header: bool = True) -> str:
    cells = []
    for index, row in enumerate(rows):
        tag = "th" if header and index == 0 else "td"
        cells.append("<tr>" + "".join(f"<{tag}>{html.escape(str(cell))}</{tag}>" for cell in row) + "</tr>")
    return "<table>" + "".join(cells) + "</table>"


def _cell_text(budget: dict) -> str:
    installed, read, tilt = budget["installation_band_c"], budget["temperature_band_c"], budget["tilt_band_deg"]
    return (
        f"installed at {installed[0]:g} to {installed[1]:g} °C, read at {read[0]:g} to {read[1]:g} °C, "
        f"|tilt| {tilt[0]:g}-{tilt[1]:g}°"
    )


def html_page(document: dict, png: bytes) -> str:
    number = html.escape(document["certificate_number"])
    budgets = "".join(
        f"<h3>Budget of the largest U on {axis}: {_cell_text(b)}</h3>" + _html_table(budget_rows(b))
        for axis, b in document["budget"].items()
    )
    u_tables = "".join(
        f"<h3>{html.escape(u_table_title(axis, table, k))}</h3>" + _html_table(u_table_rows(table, k))
        for axis, table in document["uncertainty_table"].items()
        for k in range(len(table["tilt_bands_deg"]))
    )
    statements = "".join(f"<p>{html.escape(text)}</p>" for text in document["statements"])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Calibration certificate {number}</title>
<style>body{{font-family:sans-serif;max-width:64em;margin:2em auto}}table{{border-collapse:collapse;margin:0.5em 0}}
td,th{{border:1px solid #ccc;padding:2px 6px;font-size:85%;vertical-align:top}}.big{{font-size:130%}}
.number{{float:right;font-weight:bold}}</style></head><body>
<div class="number">Certificate No. {number}</div>
<h1>{html.escape(document["title"])}</h1>
{_html_table(field_rows(document), header=False)}
<h2>Measurand</h2><p>{html.escape(document["measurand"])}</p>
<p class="big">Largest expanded uncertainty over the domain: <b>U = {two_significant_text(document["tilt_u95_deg"])}°</b>
(k = {document["coverage_factor"]:.2f}, coverage probability {document["coverage_probability"]:.0%});
per axis: {", ".join(f"{axis} {two_significant_text(value)}°" for axis, value in document["u95_max_deg"].items())}.</p>
<h2>Expanded uncertainty U of the change (°, k from the cell's effective degrees of freedom, p = 95 %)</h2>{u_tables}
<img src="data:image/png;base64,{base64.b64encode(png).decode()}" alt="U and the calibration points' errors" width="100%">
<h2>Uncertainty budget</h2>{budgets}
<p><small>{html.escape(document["method"])}</small></p>
<h2>Results at the calibration points</h2>{_html_table(point_rows(document))}
<h2>Validity</h2><ul>{"".join(f"<li>{html.escape(text)}</li>" for text in document["validity"])}</ul>
{statements}
<p>Authorised by: {html.escape(document["authorisation"]["authorised_by"])} &nbsp; Signature: ____________</p>
<p><b>{html.escape(document["end"])} {number}</b></p>
</body></html>
"""


def pdf_document(document: dict, png: bytes) -> bytes:
    """The certificate as a PDF (ReportLab's platypus), the number in every page's header."""
    from reportlab.lib import colors
    from reportlab.lib.pagesizes import A4, landscape
    from reportlab.lib.styles import getSampleStyleSheet
    from reportlab.lib.units import mm
    from reportlab.platypus import Image, Paragraph, SimpleDocTemplate, Spacer, Table, TableStyle

    styles = getSampleStyleSheet()
    small = styles["BodyText"].clone("small", fontSize=7, leading=8.5)
    number = document["certificate_number"]
    page_size = landscape(A4)

    def header(canvas, doc) -> None:
        canvas.saveState()
        canvas.setFont("Helvetica", 8)
        canvas.drawString(15 * mm, page_size[1] - 10 * mm, f"Certificate No. {number}")
        canvas.drawRightString(page_size[0] - 15 * mm, page_size[1] - 10 * mm, f"Page {doc.page}")
        canvas.restoreState()

    def table(rows: list[list[str]], widths: list[float] | None = None) -> Table:
        body = [[Paragraph(html.escape(str(cell)), small) for cell in row] for row in rows]
        result = Table(body, colWidths=widths, repeatRows=1)
        result.setStyle(
            TableStyle([("GRID", (0, 0), (-1, -1), 0.25, colors.grey), ("VALIGN", (0, 0), (-1, -1), "TOP")])
        )
        return result

    story = [
        Paragraph(html.escape(document["title"]), styles["Title"]),
        table(field_rows(document), [70 * mm, 190 * mm]),
    ]
    story += [Spacer(1, 4 * mm), Paragraph("Measurand: " + html.escape(document["measurand"]), small)]
    story.append(
        Paragraph(
            f"<b>Largest U over the domain: {two_significant_text(document['tilt_u95_deg'])}° (k = {document['coverage_factor']:.2f}, "
            f"p = 95 %)</b>; per axis: "
            + ", ".join(f"{axis} {two_significant_text(value)}°" for axis, value in document["u95_max_deg"].items()),
            styles["BodyText"],
        )
    )
    for axis, u_table in document["uncertainty_table"].items():
        for k in range(len(u_table["tilt_bands_deg"])):
            story += [
                Paragraph(
                    f"Expanded uncertainty U of the change (°), {u_table_title(axis, u_table, k)}", styles["Heading3"]
                ),
                table(u_table_rows(u_table, k)),
            ]
    story += [Image(io.BytesIO(png), width=250 * mm, height=250 * mm * 4.0 / 11.0)]
    for axis, budget in document["budget"].items():
        story += [
            Paragraph(f"Uncertainty budget of the largest U on {axis}: {_cell_text(budget)}", styles["Heading3"]),
            table(budget_rows(budget), [width * mm for width in BUDGET_WIDTHS_MM]),
        ]
    story += [Paragraph(html.escape(document["method"]), small)]
    story += [Paragraph("Results at the calibration points", styles["Heading3"]), table(point_rows(document))]
    story += [Paragraph("Validity", styles["Heading3"])] + [
        Paragraph(html.escape(text), small) for text in document["validity"]
    ]
    story += [Spacer(1, 3 * mm)] + [Paragraph(html.escape(text), small) for text in document["statements"]]
    story += [
        Paragraph(
            f"Authorised by: {html.escape(document['authorisation']['authorised_by'])}   Signature: ____________", small
        ),
        Paragraph(f"<b>{html.escape(document['end'])} {html.escape(number)}</b>", styles["BodyText"]),
    ]
    buffer = io.BytesIO()
    SimpleDocTemplate(
        buffer, pagesize=page_size, title=f"Calibration certificate {number}", topMargin=16 * mm, bottomMargin=12 * mm
    ).build(story, onFirstPage=header, onLaterPages=header)
    return buffer.getvalue()
