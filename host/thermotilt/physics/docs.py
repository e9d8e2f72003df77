"""The tables of docs/physics-model.md, made from the term declarations.

`python -m thermotilt.physics.docs` rewrites each block between
`<!-- generated: NAME -->` and `<!-- end: NAME -->` in that file;
host/tests/test_physics.py checks that the file holds what this makes.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path
from typing import Any

from .model import DECLARATIONS
from .parameters import Bounds, Parameter, PerAxis, Surfaces
from .terms import HARDWARE, REGISTRY, SENSOR_STAGES, ChamberTerm, SensorTerm

DOC = Path(__file__).resolve().parents[3] / "docs" / "physics-model.md"
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _number(value: float) -> str:
    if value < 0:
        return "−" + _number(-value)
    if value == int(value):
        exponent = math.log10(value) if value > 0 else 0.0
        if value >= 1e6 and exponent == int(exponent):
            return "10" + str(int(exponent)).translate(_SUPERSCRIPT)
        return str(int(value))
    mantissa, _, exponent = f"{value:.3g}".partition("e")
    return f"{mantissa}·10{str(int(exponent)).translate(_SUPERSCRIPT)}" if exponent else mantissa


def _unit(unit: str) -> str:
    return f" {unit.replace('degC', '°C').replace('ohm', 'Ω')}" if unit else ""


def _range(bounds: Bounds) -> str:
    if bounds.low == -bounds.high and bounds.high > 0:
        return f"±{_number(bounds.high)}{_unit(bounds.unit)}"
    low = f"> {_number(bounds.low)}" if bounds.low_exclusive else _number(bounds.low)
    return f"{low} … {_number(bounds.high)}{_unit(bounds.unit)}"


def _label_and_range(section: str, parameter: Parameter) -> tuple[str, str]:
    label = f"`[{section}] {parameter.name}`"
    kind = parameter.kind
    if isinstance(kind, PerAxis):
        return f"{label} {', '.join(kind.keys)}", _range(kind.bounds)
    if isinstance(kind, Surfaces):
        names = ", ".join(kind.term_names)
        return f"{label} {names}", ", ".join(f"±{_number(b.high)}" for b in kind.term_bounds)
    assert isinstance(kind, Bounds)
    return label, _range(kind)


def ranges_table() -> str:
    rows = ["| parameter | range | why |", "|---|---|---|"]
    for section, parameters in DECLARATIONS.items():
        for parameter in parameters:
            if parameter.name != "enabled":
                label, cell = _label_and_range(section, parameter)
                rows.append(f"| {label} | {cell} | {parameter.why} |")
    return "\n".join(rows)


def _default(parameter: Parameter) -> str:
    value: Any = parameter.default
    unit = ""
    if isinstance(parameter.kind, (Bounds, PerAxis)):
        bounds = parameter.kind.bounds if isinstance(parameter.kind, PerAxis) else parameter.kind
        unit = _unit(bounds.unit)
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, dict):
        return ", ".join(f"{axis} = {_number(number)}" for axis, number in value.items()) + unit
    if isinstance(value, str):
        return f'`"{value}"`'
    return f"{value:.10g}".replace("-", "−") + unit


def _term_rows(names: list[str], with_stage: bool) -> list[str]:
    head = ["term", *(["stage"] if with_stage else []), "effect", "parameter", "default", "source"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in names:
        declared = REGISTRY.get(name) or HARDWARE[name]
        if name in HARDWARE:
            label = f"`[{name}]`"
        elif declared.enabled_by_default:
            label = f"`{name}`"
        else:
            label = f"`{name}` (off by default)"
        stage = [f"`{declared.stage}`" if issubclass(declared, SensorTerm) else ""]
        first = [label, *(stage if with_stage else []), declared.summary]
        parameters = [p for p in DECLARATIONS[name] if p.name != "enabled"]
        cells = [[f"`{p.name}`", _default(p), p.source] for p in parameters] or [["—", "—", "—"]]
        for index, parameter_cells in enumerate(cells):
            lead = first if index == 0 else [""] * len(first)
            rows.append("| " + " | ".join([*lead, *parameter_cells]) + " |")
    return rows


def chamber_table() -> str:
    names = ["chamber", *(name for name, term in REGISTRY.items() if issubclass(term, ChamberTerm))]
    return "\n".join(_term_rows(names, with_stage=False))


def sensor_table() -> str:
    names = ["sensor", *(name for name, term in REGISTRY.items() if issubclass(term, SensorTerm))]
    stages = ["| stage | a term there is called with and returns |", "|---|---|"]
    stages += [f"| `{stage}` | {signature} |" for stage, signature in SENSOR_STAGES.items()]
    return "\n".join(stages) + "\n\n" + "\n".join(_term_rows(names, with_stage=True))


BLOCKS = {"ranges": ranges_table, "chamber terms": chamber_table, "sensor terms": sensor_table}


def _block(name: str) -> re.Pattern[str]:
    return re.compile(rf"(<!-- generated: {name} -->\n)(?:.*?\n)?(<!-- end: {name} -->)", re.S)


def rendered(text: str) -> str:
    """The document with every generated block made anew."""
    for name, make in BLOCKS.items():
        text, count = _block(name).subn(lambda match: match[1] + make() + "\n" + match[2], text)
        if count != 1:
            raise ValueError(f"{DOC}: expected one block '{name}', found {count}")
    return text


def main() -> None:
    text = DOC.read_text(encoding="utf-8")
    new = rendered(text)
    if new != text:
        DOC.write_text(new, encoding="utf-8")
        print(f"rewrote {DOC}", file=sys.stderr)


if __name__ == "__main__":
    main()
