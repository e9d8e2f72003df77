"""What the benchmarks' committed records share: a share of runs with its
Wilson 95 % interval (statsmodels' proportion_confint), and the digest of
what a row's outcome depends on, so that a row made by other code or another
default model is known stale and runs again."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from statsmodels.stats.proportion import proportion_confint

from .physics import Model
from .physics.document import model_document

PACKAGE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Share:
    """count of runs out of runs, with its Wilson interval at 95 %."""

    count: int
    runs: int

    @property
    def share(self) -> float:
        return self.count / self.runs if self.runs else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        if not self.runs:
            return float("nan"), float("nan")
        low, high = proportion_confint(self.count, self.runs, alpha=0.05, method="wilson")
        return float(low), float(high)

    def shown(self, percent: Callable[[float], str]) -> str:
        """count/runs = share (low–high), each percentage by percent; – without runs."""
        if not self.runs:
            return "–"
        low, high = self.interval
        return f"{self.count}/{self.runs} = {percent(self.share)} ({percent(low)}–{percent(high)})"


def sources_digest(sources: Iterable[str]) -> hashlib.blake2b:
    """A blake2b of the package's sources named (files, or folders whose .py
    and .toml files count), as this process reads them, and of the default
    model as loaded; the caller adds what else its rows depend on."""
    digest = hashlib.blake2b(digest_size=6)
    for source in sources:
        path = PACKAGE / source
        files = sorted(path.rglob("*")) if path.is_dir() else [path]
        for file in files:
            if file.suffix in (".py", ".toml") and file.is_file():
                digest.update(file.relative_to(PACKAGE).as_posix().encode())
                digest.update(file.read_bytes())
    digest.update(json.dumps(model_document(Model.load()), sort_keys=True).encode())
    return digest
