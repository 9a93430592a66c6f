"""fractalc's own cache folder (`cache_dir`): the lane and device choices,
the drivers' kernel caches, build locks, the vendors folder of the drivers
fractalc registers."""
from __future__ import annotations

import os
from pathlib import Path

CACHE_ENVIRONMENT = "FRACTALC_CACHE_DIR"


def cache_dir() -> Path:
    """$FRACTALC_CACHE_DIR, else the XDG cache's `fractalc` folder."""
    if os.environ.get(CACHE_ENVIRONMENT):
        return Path(os.environ[CACHE_ENVIRONMENT])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "fractalc"
