"""The pages `make bench` and `make demo` write into docs/: what they
measured, with when, on what machine and by which command, so that a figure
on a page always says where it came from. Nobody edits these pages by hand:
the command that wrote one writes it again."""

from __future__ import annotations

import datetime
import os
import platform
import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                key, _, value = line.partition(":")
                if key.strip() == "model name":
                    return value.strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _memory_gib() -> str:
    try:
        with open("/proc/meminfo", encoding="utf-8") as meminfo:
            for line in meminfo:
                if line.startswith("MemTotal:"):
                    return f"{int(line.split()[1]) / 2**20:.1f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return "unknown"


def machine() -> str:
    """What `nproc`, /proc/cpuinfo and /proc/meminfo say of this machine."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{cores} cores (nproc), {_cpu_model()}, {_memory_gib()} memory, Python {platform.python_version()}"


def load_average() -> str:
    """The 1-minute load average: other jobs on the machine slow every timed figure down."""
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except OSError:
        return "unknown"


def stamp(command: str, started: datetime.datetime, load_at_start: str) -> list[str]:
    """When, where and by what a page was written, and how long that took."""
    took_s = (now() - started).total_seconds()
    return [
        f"Written by `{command}` (do not edit: run it again to refresh the page).",
        "",
        f"- date: {started:%Y-%m-%d %H:%M} UTC",
        f"- machine: {machine()}",
        f"- load average when it started: {load_at_start} (other jobs slow the timed figures down)",
        f"- command: `{command}`, which took {took_s // 60:.0f} min {took_s % 60:.0f} s",
    ]


def table(header: tuple[str, ...], rows: list[tuple]) -> list[str]:
    def cell(value) -> str:
        return str(value).replace("|", "\\|").replace("\n", " ")

    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + [
        "| " + " | ".join(cell(value) for value in row) + " |" for row in rows
    ]


def now() -> datetime.datetime:
    return datetime.datetime.now(datetime.UTC)


def write(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines).rstrip("\n") + "\n", encoding="utf-8")
    print(f"wrote {path}", flush=True)


def write_block(document: Path, begin: str, end: str, text: str) -> None:
    """Replace what lies between the begin and end markers in a page that
    people write the rest of; a page that does not exist yet is written with
    that block alone. ValueError when the page has no such block."""
    block = f"{begin}\n\n{text}\n{end}"
    if not document.exists():
        document.parent.mkdir(parents=True, exist_ok=True)
        document.write_text(block + "\n", encoding="utf-8")
        return
    content = document.read_text(encoding="utf-8")
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    if not pattern.search(content):
        raise ValueError(f"{document} has no {begin} ... {end} block")
    document.write_text(pattern.sub(lambda _: block, content), encoding="utf-8")
