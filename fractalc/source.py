"""Reading a scene file: what counts as one, its size limit and its encoding.

The API (`load`) and every CLI command read scene files through
`read_scene_file`, so they accept and refuse the same files with the same
messages.
"""
from __future__ import annotations

import codecs
import os
import stat

from .errors import LINE_BREAK, Diagnostic, NoSceneFile, RenderError, SceneError, visible

MAX_FILE_BYTES = 8 * 1024 * 1024

# O_NONBLOCK: opening a FIFO must not wait for a writer before the type check
# refuses it (it does not change reading a regular file). Flags a platform
# lacks are left out.
_OPEN_FLAGS = os.O_RDONLY | sum(getattr(os, flag, 0) for flag in ("O_NONBLOCK", "O_NOCTTY", "O_CLOEXEC", "O_BINARY"))

_FILE_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
               (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"))


def read_scene_file(path: str) -> str:
    """The text of the scene file at `path`. Raise `NoSceneFile` when `path`
    names no regular file, `RenderError` when it cannot be read, and
    `SceneError` when it is over MAX_FILE_BYTES or not UTF-8."""
    try:
        fd = os.open(path, _OPEN_FLAGS)
    except FileNotFoundError:
        raise NoSceneFile(f"cannot read {visible(path)}: no such file") from None
    except OSError as error:
        raise RenderError(f"cannot read {visible(path)}: {error.strerror}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = next((word for is_kind, word in _FILE_KINDS if is_kind(mode)), "not a regular file")
            raise NoSceneFile(f"cannot read {visible(path)}: it is {kind}, not a scene file")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise RenderError(f"cannot read {visible(path)}: {error.strerror}") from None
    finally:
        os.close(fd)
    return decode_scene(data, path)


def decode_scene(data: bytes, path: str) -> str:
    """Scene bytes as text: UTF-8, a leading byte order mark ignored."""
    if len(data) > MAX_FILE_BYTES:
        first_line = LINE_BREAK.split(data[:200].decode("utf-8", errors="backslashreplace"), 1)[0]
        raise SceneError([Diagnostic(path, 1, 1, f"the scene file is larger than "
                                                 f"{MAX_FILE_BYTES // (1024 * 1024)} MB", first_line)])
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8):]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError([_invalid_utf8(data, error, path)]) from None


def _invalid_utf8(data: bytes, error: UnicodeDecodeError, path: str) -> Diagnostic:
    """Where the first invalid byte sequence is, by the lines and columns of
    the text before it; the line is quoted with the bad bytes as \\xNN."""
    lines = LINE_BREAK.split(data[:error.start].decode("utf-8"))
    # "\n" and "\r" bytes are never part of a multi-byte UTF-8 character.
    line_start = max(data.rfind(b"\n", 0, error.start), data.rfind(b"\r", 0, error.start)) + 1
    line_end = min((i for i in (data.find(b"\n", error.start), data.find(b"\r", error.start)) if i >= 0),
                   default=len(data))
    line = data[line_start:line_end].decode("utf-8", errors="backslashreplace")
    bad = data[error.start:error.end]
    message = f"invalid UTF-8 (byte{'s' if len(bad) > 1 else ''} {' '.join(f'0x{b:02x}' for b in bad)}); " \
              "scene files are UTF-8 text"
    return Diagnostic(path, len(lines), len(lines[-1]) + 1, message, line, len(bad) * 4)
