#!/usr/bin/env python3
"""Generate host/thermotilt/wire/protocol_spec.py from lib/Protocol/src/ProtocolFrames.def.

The .def file is the one definition of the serial protocol (frames, ERR codes
and their detail tokens); the firmware
includes it, the host package uses the module generated here. Run without
arguments to rewrite the module, with --check to exit 1 when it is stale.
"""

import argparse
import json
import re
import sys
from pathlib import Path

HOST_DIR = Path(__file__).resolve().parents[1]
DEFINITION = HOST_DIR.parent / "lib" / "Protocol" / "src" / "ProtocolFrames.def"
MODULE = HOST_DIR / "thermotilt" / "wire" / "protocol_spec.py"

_DEFINE = re.compile(r"^#define THERMOTILT_PROTOCOL_(\w+) (\d+)$", re.MULTILINE)
_FRAME = re.compile(r'^THERMOTILT_FRAME\((\w+), (STREAM|ANSWER|OUTCOME|COMMAND), "([^"]*)"\)$', re.MULTILINE)
_ERROR = re.compile(r'^THERMOTILT_ERROR\(([A-Z][A-Z0-9_]*), "([^"]+)"\)$', re.MULTILINE)
_ERROR_DETAIL = re.compile(r'^THERMOTILT_ERROR_DETAIL\(([A-Z][A-Z0-9_]*), "([A-Z0-9_ ]+)"\)$', re.MULTILINE)
_FIELD = re.compile(r"^([a-z][a-z0-9_]*):([ift])$")
_MACRO_LINE = re.compile(r"^THERMOTILT_(\w+)\((.*?)\)\s*(?://.*)?$", re.MULTILINE)
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
# The lines that say which firmware enumerator reports a detail token or an
# ERR code: their arguments, and the codes each line's TOKEN must be carried
# by besides its CODE.
_ENUM_LINES = {
    "MALFORMED_REASON": (("TOKEN",), ("BAD_FRAME",)),
    "CHAMBER_FAULT": (("TOKEN", "CODE"), ("FAULT",)),
    "PROGRAM_ERROR": (("ENUMERATOR", "TOKEN"), ("BAD_ARG",)),
    "GUARD_ERROR": (("ENUMERATOR", "TOKEN"), ("BAD_ARG",)),
    "SENSOR_STATUS": (("ENUMERATOR", "TOKEN"), ("SENSOR_MISSING",)),
    "BLOCK_STATUS": (("ENUMERATOR", "CODE"), ()),
}
_DEFINITION_LINES = {"FRAME", "ERROR", "ERROR_DETAIL"}
_CONSTANTS = ("VERSION", "MAX_LINE", "MAX_FIELDS")


class DefinitionError(ValueError):
    pass


def _count_lines(text, prefix):
    return sum(1 for line in text.splitlines() if line.startswith(prefix))


def parse_errors(text):
    """Return [(code, meaning, [detail token, ...])] in the order of the file."""
    if _count_lines(text, "THERMOTILT_ERROR(") != len(_ERROR.findall(text)):
        raise DefinitionError("a THERMOTILT_ERROR line does not match the expected form")
    if _count_lines(text, "THERMOTILT_ERROR_DETAIL(") != len(_ERROR_DETAIL.findall(text)):
        raise DefinitionError("a THERMOTILT_ERROR_DETAIL line does not match the expected form")
    errors = {}
    for code, meaning in _ERROR.findall(text):
        if code in errors:
            raise DefinitionError(f"ERR code {code} is defined twice")
        errors[code] = (meaning, [])
    seen = set()
    for token, codes in _ERROR_DETAIL.findall(text):
        if token in seen:
            raise DefinitionError(f"detail token {token} is defined twice")
        seen.add(token)
        for code in codes.split():
            if code not in errors:
                raise DefinitionError(f"detail token {token}: no ERR code {code}")
            errors[code][1].append(token)
    return [(code, meaning, details) for code, (meaning, details) in errors.items()]


def check_enum_lines(text, errors):
    """Refuse a line of an unknown macro, and an enumerator line whose token
    or code the file does not define, or that its code does not carry."""
    carried = {code: set(details) for code, _, details in errors}
    seen = set()
    for macro, arguments in _MACRO_LINE.findall(text):
        if macro in _DEFINITION_LINES:
            continue
        if macro not in _ENUM_LINES:
            raise DefinitionError(f"THERMOTILT_{macro}: no such line")
        layout, carriers = _ENUM_LINES[macro]
        values = [value.strip() for value in arguments.split(",")]
        if len(values) != len(layout) or not all(_NAME.match(value) for value in values):
            raise DefinitionError(f"THERMOTILT_{macro}({arguments}): expected ({', '.join(layout)})")
        named = dict(zip(layout, values))
        if (macro, values[0]) in seen:
            raise DefinitionError(f"THERMOTILT_{macro}: {values[0]} is named twice")
        seen.add((macro, values[0]))
        code = named.get("CODE")
        if code is not None and code not in carried:
            raise DefinitionError(f"THERMOTILT_{macro}({arguments}): no ERR code {code}")
        token = named.get("TOKEN")
        if token is not None:
            for carrier in carriers + ((code,) if code else ()):
                if token not in carried[carrier]:
                    raise DefinitionError(f"THERMOTILT_{macro}({arguments}): ERR {carrier} does not carry {token}")
    if _count_lines(text, "THERMOTILT_") != len(_MACRO_LINE.findall(text)):
        raise DefinitionError("a THERMOTILT_ line does not match the expected form")


def parse_definition(text):
    """Return (constants, frames) where frames is [(tag, direction, role, [(name, kind)])]:
    a COMMAND goes from the host to a board, every other role the other way."""
    constants = {name: int(value) for name, value in _DEFINE.findall(text)}
    missing = [name for name in _CONSTANTS if name not in constants]
    if missing:
        raise DefinitionError(f"missing #define THERMOTILT_PROTOCOL_{missing[0]}")
    frames = []
    for tag, role, field_list in _FRAME.findall(text):
        fields = []
        for item in field_list.split(",") if field_list else []:
            match = _FIELD.match(item)
            if not match:
                raise DefinitionError(f"{tag}: bad field {item!r}, expected name:i|f|t")
            fields.append((match.group(1), match.group(2)))
        direction = "host" if role == "COMMAND" else "board"
        frames.append((tag, direction, role.lower(), fields))
    if _count_lines(text, "THERMOTILT_FRAME(") != len(frames):
        raise DefinitionError("a THERMOTILT_FRAME line does not match the expected form")
    return constants, frames


def render(text):
    constants, frames = parse_definition(text)
    errors = parse_errors(text)
    check_enum_lines(text, errors)
    lines = [
        "# Generated by host/tools/generate_protocol_spec.py from",
        "# lib/Protocol/src/ProtocolFrames.def. Do not edit; run the generator.",
        "",
        f"PROTOCOL_VERSION = {constants['VERSION']}",
        f"MAX_LINE = {constants['MAX_LINE']}",
        f"MAX_FIELDS = {constants['MAX_FIELDS']}",
        "",
        "# tag: (direction, role, ((field name, kind), ...)); kind i integer, f float,",
        "# t token. role: stream (sent on the board's own schedule), answer (the data",
        "# a query returns before its ACK), outcome (ACK, ERR) or command.",
        "FRAMES = {",
    ]
    for tag, direction, role, fields in frames:
        if not fields:
            lines.append(f'    "{tag}": ("{direction}", "{role}", ()),')
            continue
        lines.append(f'    "{tag}": (')
        lines.append(f'        "{direction}",')
        lines.append(f'        "{role}",')
        lines.append("        (")
        lines.extend(f'            ("{name}", "{kind}"),' for name, kind in fields)
        lines.append("        ),")
        lines.append("    ),")
    lines.append("}")
    lines.append("")
    lines.append("# ERR code: (when a board sends it, (detail tokens, ...)); a code without")
    lines.append("# tokens carries a frame TYPE as its detail")
    lines.append("ERRORS = {")
    for code, meaning, details in errors:
        lines.append(f'    "{code}": (')
        lines.append(f"        {json.dumps(meaning)},")
        if details:
            lines.append("        (")
            lines.extend(f'            "{token}",' for token in details)
            lines.append("        ),")
        else:
            lines.append("        (),")
        lines.append("    ),")
    lines.append("}")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the module is stale")
    args = parser.parse_args(argv)
    try:
        expected = render(DEFINITION.read_text())
    except (OSError, DefinitionError) as error:
        print(f"generate_protocol_spec: {error}", file=sys.stderr)
        return 2
    current = MODULE.read_text() if MODULE.exists() else ""
    if args.check:
        if current != expected:
            print(f"{MODULE} is stale: run host/tools/generate_protocol_spec.py", file=sys.stderr)
            return 1
        return 0
    if current != expected:
        MODULE.write_text(expected)
    return 0


if __name__ == "__main__":
    sys.exit(main())
