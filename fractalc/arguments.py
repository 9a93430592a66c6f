"""The numeric arguments of commands and API calls that are not a scene
file's keys (`--rays`, `--fps`, `mesh --resolution`, a render's seed, ...):
their types and ranges, declared once as the file's keys are
(program.RENDER_KEYS) and checked by the same function (check.check_value),
so that a command-line option and the API argument it becomes refuse the
same values in the same words. Numbers on the command line are read by
`parse_number`, in ASCII digits as in a scene file.
"""
from __future__ import annotations

import re
from dataclasses import replace

from .check import check_value
from .program import RENDER_KEYS
from .types import Parameter, Type, above, at_most, below, between

SEED_LIMIT = 2 ** 32       # seeds are the kernel's 32-bit unsigned integers
MAX_RESOLUTION = 16384     # mesh cells along the longest side (docs/meshes.md)

ARGUMENTS = {p.name: p for p in (
    Parameter("seed", Type.WHOLE, None, (between(0, SEED_LIMIT - 1),)),
    Parameter("rays", Type.WHOLE, None, (between(1, 1000000),)),                 # check --de
    Parameter("surface", Type.NUMBER, None, (above(0), below(1))),               # check --de, in bound radii
    Parameter("fps", Type.NUMBER, None, (above(0), at_most(1000))),              # animate
    Parameter("frames", Type.WHOLE, None, (between(1, 100000),)),                # bench, view --benchmark
    Parameter("repeat", Type.WHOLE, None, (between(1, 1000),)),                  # bench
    Parameter("resolution", Type.WHOLE, None, (between(2, MAX_RESOLUTION),)),    # mesh
    Parameter("min_volume", Type.NUMBER, None, (above(0),)),                     # mesh --shells solid: bodies kept
    Parameter("workers", Type.WHOLE, None, (between(1, 1024),)),                 # a local render farm
    Parameter("preview_scale", Type.WHOLE, None, (between(1, 64),)),             # view, studio
    Parameter("port", Type.WHOLE, None, (between(0, 65535),)),                   # studio (0: any free port)
    Parameter("bits", Type.WHOLE, None, (between(8, 16),)),                      # PNG output: 8 or 16
    replace(RENDER_KEYS["samples"], name="max_samples"),              # view: a still's samples
    replace(RENDER_KEYS["height"], name="tile_rows"),                 # a render farm's tiles
)}

_NUMBER = re.compile(r"[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|inf|infinity|nan)", re.ASCII | re.IGNORECASE)


def parse_number(text: str) -> float:
    """A number written on the command line: ASCII digits (as in a scene
    file; `float` would also take '٣'), or inf or nan, which the ranges
    then refuse in words; ValueError for anything else."""
    if not _NUMBER.fullmatch(text.strip()):
        raise ValueError(f"'{text}' is not a number (digits 0-9, as in 2, -0.5 or 1e3)")
    return float(text)


def spec(name: str) -> Parameter:
    """The type and range of the argument `name` (a render key's own)."""
    return ARGUMENTS.get(name) or RENDER_KEYS[name]


def checked(name: str, value, subject: str | None = None):
    """`value` as the argument `name` takes it (an int for whole numbers);
    ValueError saying what is wrong, of `subject` (default: the name;
    '' for none, when the caller names it)."""
    return check_value(spec(name), name, value, repr(name) if subject is None else subject)


def require_type(name: str, value, types: type | tuple[type, ...], takes: str) -> None:
    """TypeError naming the argument `name` and what it `takes` where
    `value` is not one of `types` (a bool is never a number here)."""
    if not isinstance(value, types) or (isinstance(value, bool) and bool not in (
            types if isinstance(types, tuple) else (types,))):
        shown = repr(value) if len(repr(value)) <= 60 else type(value).__name__
        raise TypeError(f"{name} must be {takes}, not {shown}")
