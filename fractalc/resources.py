"""Where the grammar and the OpenCL library live: inside the installed
package (`fractalc.grammar`, `fractalc.stdlib_cl`) or, in a source checkout,
beside the package."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

_CHECKOUT = Path(__file__).resolve().parent.parent


def resource_dir(name: str) -> Path:
    try:
        found = Path(str(resources.files(f"fractalc.{name}")))
        if found.is_dir():
            return found
    except ModuleNotFoundError:
        pass
    return _CHECKOUT / name
