"""Where the grammar and the OpenCL library live: inside the installed
package (`fractalc/grammar`, `fractalc/stdlib_cl`) or, in a source checkout,
beside the package."""
from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def resource_dir(name: str) -> Path:
    installed = _PACKAGE / name
    return installed if installed.is_dir() else _PACKAGE.parent / name
