"""Where the offline build (`make build`) puts what the host loads: the
firmware images, the twin's library and the firmware's algorithms compiled
for the host."""

import os
from pathlib import Path


def build_dir() -> Path:
    """The offline build tree: $THERMOTILT_BUILD_DIR, else <repo>/build."""
    override = os.environ.get("THERMOTILT_BUILD_DIR")
    if override:
        return Path(override)
    return Path(__file__).resolve().parents[2] / "build"
