"""`fractalc studio`: a scene's text, its controls and its live image in a
web browser, on this machine or, over an SSH tunnel, a remote one
(docs/studio.md).

    edits     minimal edits of the scene text at its spans (saving, key controls)
    controls  what the page's controls show, from the language's key specs
    live      the thread that checks the text and renders the newest view
    jobs      final renders in the background, and their command lines
    session   the studio's state and the page's requests
    server    Tornado: the page, its files, one WebSocket per page; the guard
    static/   the page itself (plain HTML, CSS and JavaScript, no build step)
"""
from __future__ import annotations

from importlib.util import find_spec

MISSING_EXTRA = "fractalc studio needs tornado and pillow: pip install 'fractalc[studio]'"


def installed() -> bool:
    """Whether the studio extra's packages are there."""
    return all(find_spec(name) is not None for name in ("tornado", "PIL"))
