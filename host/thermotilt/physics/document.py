"""A model as the document of a model file: what `Model.from_document` reads
back to the same model, so a changed model can be written and used again."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomli_w

from .model import Model


def plain(value: Any) -> Any:
    """A value of a model as plain TOML data: tables as dicts, lists for tuples."""
    if isinstance(value, Mapping):
        return {key: plain(item) for key, item in value.items()}
    if isinstance(value, tuple):
        return [plain(item) for item in value]
    return value


def model_document(model: Model) -> dict[str, Any]:
    """Every hardware section and term with all its values, the faults, and
    a batch's sensors with the terms each overrides."""
    document: dict[str, Any] = {name: plain(values) for name, values in model.constants.items()}
    document.update({name: plain(values) for name, values in model.terms.items()})
    faults = []
    for fault in model.faults:
        table: dict[str, Any] = {"name": fault.name, "start_s": fault.start_s}
        if fault.end_s is not None:
            table["end_s"] = fault.end_s
        if fault.rate is not None:
            table["rate"] = fault.rate
        faults.append(table)
    if faults:
        document["faults"] = faults
    if model.sensors:
        document["sensors"] = [
            {"id": sensor.id, **{name: plain(values) for name, values in sensor.terms.items()}}
            for sensor in model.sensors
        ]
    return document


def with_values(model: Model, term: str, values: Mapping[str, Any]) -> Model:
    """A copy with a term's parameters changed (and checked against their
    declarations, as a model file's are)."""
    document = model_document(model)
    if term not in document:
        raise KeyError(term)
    document[term] = {**document[term], **plain(values)}
    return Model.from_document(document, model.source)


def write_model(model: Model, path: Path, header: str = "") -> None:
    """The model as a complete model file (every table spelled out)."""
    comments = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    path.write_text(comments + tomli_w.dumps(model_document(model)), encoding="utf-8")
