"""The RAM of each Unity test program on the Nano (ATmega328P): its static
data and the SRAM its stack never reached in a whole run, as sim/avr_run
reports them; written into docs/testing.md by `make bench` (or this script
alone), for the offline build and, when UNITY_ROOT names a checkout of
ThrowTheSwitch's Unity (the one `pio test` installs), for the same tests
built with it, which is what PlatformIO's build holds.

Usage: THERMOTILT_BUILD_DIR=build [UNITY_ROOT=DIR] nano_ram.py [--page FILE]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
from pathlib import Path

import generated_page

from thermotilt.build_tree import build_dir

ROOT = Path(__file__).resolve().parents[2]
MCU = "atmega328p"
PAGE = generated_page.DOCS / "testing.md"
BEGIN = "<!-- make bench writes the Nano test programs' RAM from here on (host/tools/nano_ram.py) -->"
END = "<!-- /test-ram -->"
# sim/avr_run's closing line of a Unity run.
RAM_LINE = re.compile(r"^avr_run: RAM (\d+) B: static (\d+) B, stack untouched (\d+) B$", re.MULTILINE)
UNITY_VERSION = re.compile(r"^ThrowTheSwitch Unity (\S+)")


def test_programs() -> list[str]:
    return sorted(folder.name for folder in (ROOT / "test").glob("test_*") if folder.is_dir())


def unity_of(tree: Path) -> str:
    """Which Unity a tree was built with (cmake/unity.cmake), in a few words."""
    for line in (tree / "CMakeCache.txt").read_text(encoding="utf-8").splitlines():
        if line.startswith("THERMOTILT_UNITY:INTERNAL="):
            version = UNITY_VERSION.match(line.partition("=")[2])
            return f"Unity {version[1]}" if version else "cmake/unity's fallback"
    return "an unknown Unity"


def real_unity_tree(unity_root: str) -> Path:
    """The Nano's test programs built with the Unity in unity_root, beside the offline build."""
    tree = build_dir() / f"unity-{MCU}"
    subprocess.run(
        [
            "cmake",
            "-S",
            str(ROOT),
            "-B",
            str(tree),
            "-DCMAKE_TOOLCHAIN_FILE=cmake/avr-gcc.cmake",
            f"-DAVR_MCU={MCU}",
            f"-DUNITY_ROOT={unity_root}",
        ],
        check=True,
        capture_output=True,
        cwd=ROOT,
    )
    subprocess.run(["cmake", "--build", str(tree), "-j", str(os.cpu_count() or 1)], check=True, capture_output=True)
    return tree


def measure(tree: Path, program: str) -> tuple[int, int, int]:
    """(SRAM, static, stack untouched) in bytes, after the program's whole run."""
    run = subprocess.run(
        [str(build_dir() / "native" / "avr_run"), "-m", MCU, "-f", "16000000", "-t", "600", "--unity"]
        + [str(tree / f"{program}.elf")],
        capture_output=True,
        text=True,
    )
    found = RAM_LINE.search(run.stdout)
    if not found:
        raise RuntimeError(f"avr_run gave no RAM line for {program} in {tree}: {run.stderr.strip()}")
    return int(found[1]), int(found[2]), int(found[3])


def report(trees: list[Path]) -> str:
    programs = test_programs()
    figures = {tree: [measure(tree, program) for program in programs] for tree in trees}
    ram = figures[trees[0]][0][0]
    header = ["program"]
    for tree in trees:
        header += [f"static, {unity_of(tree)}", "stack untouched"]
    rows = [
        (f"`{program}`", *(value for tree in trees for value in figures[tree][index][1:]))
        for index, program in enumerate(programs)
    ]
    lines = [
        f"Bytes of the ATmega328P's {ram} B SRAM, after each program's whole run in simavr "
        f"(`avr_run`'s closing line): its static data (.data, .bss, .noinit, the Arduino core's "
        f"Serial among them) and the bytes above it its stack never reached. Written by "
        f"`make bench` on {generated_page.now():%Y-%m-%d}.",
        "",
        *generated_page.table(tuple(header), rows),
    ]
    if len(trees) == 1:
        lines += ["", "Unity 2.6.1, PlatformIO's, was not measured: `UNITY_ROOT=DIR make bench` adds it."]
    least = min((figures[tree][index][2], program) for tree in trees for index, program in enumerate(programs))
    lines += ["", f"Least untouched: {least[0]} B (`{least[1]}`)."]
    return "\n".join(lines)


def write(page: Path = PAGE) -> str:
    trees = [build_dir() / MCU]
    unity_root = os.environ.get("UNITY_ROOT")
    if unity_root:
        trees.append(real_unity_tree(unity_root))
    text = report(trees)
    generated_page.write_block(page, BEGIN, END, text)
    print(text)
    print(f"wrote {page}", flush=True)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--page", type=Path, default=PAGE, help=f"the page to write into (default {PAGE})")
    write(parser.parse_args().page)
