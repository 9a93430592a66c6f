"""First images: every fenced `frac` block of README.md and docs/*.md
renders, as written, a whole subject in frame.

Each block is rendered tiny (64 x 48, one sample, one ray per work-item:
the build is the cost, and one lane builds fastest) without its ground:
the planes among the operands of the scene's top-level union, which reach
to the horizon and so fill any view that looks down on them. What is left
is the subject: its hit pixels must not be empty, and must not touch all
four borders of the image (clipped fragments, or a camera inside the
subject, do). A 360-degree view has no frame, a scene of planes alone no
subject, and a fragment (a block with no `scene`, e.g. a preset to add to
a file) nothing to render: each is said so, and skipped.

Cost (57 blocks, 55 kernels): 45 s of CPU with cold kernel caches (PoCL,
2-core EPYC), 5 s warm; one lane builds in about two thirds of the time
of sixteen (cold, all blocks: 91 s against 137 s at the blocks' own
settings).
"""
from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc.api import Scene
from fractalc.program import Combination, Primitive, Transformed, WithMaterial

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
BLOCK = re.compile(r"```frac\n(.*?)```", re.S)
SCENE = re.compile(r"^\s*scene\b", re.M)
WIDTH, HEIGHT = 64, 48
MIN_SUBJECT = 0.01        # of the image's pixels


def blocks() -> list:
    found = []
    for page in PAGES:
        for i, text in enumerate(BLOCK.findall(page.read_text())):
            found.append(pytest.param(page, text, id=f"{page.relative_to(REPO)}#{i + 1}"))
    return found


def _is_ground(shape) -> bool:
    """A plane, whatever its material and however it is moved."""
    while isinstance(shape, (WithMaterial, Transformed)):
        shape = shape.shape
    return isinstance(shape, Primitive) and shape.signature.name == "plane"


def without_ground(shape):
    """The shape less the planes among its top-level union's operands (None
    where nothing else is left)."""
    if isinstance(shape, WithMaterial):
        inner = without_ground(shape.shape)
        return None if inner is None else replace(shape, shape=inner)
    if _is_ground(shape):
        return None
    if isinstance(shape, Combination) and shape.kind == "union":
        parts = [part for part in (without_ground(s) for s in shape.shapes) if part is not None]
        if not parts:
            return None
        return parts[0] if len(parts) == 1 else replace(shape, shapes=tuple(parts))
    return shape


def test_the_pages_hold_the_examples():
    # README's tour and every page with examples: the test reads them all
    names = {page.name for page in PAGES if BLOCK.search(page.read_text())}
    assert {"README.md", "language.md", "effects.md", "looks.md", "formulas.md", "animation.md"} <= names
    assert len(blocks()) >= 50


@pytest.mark.opencl
@pytest.mark.parametrize("page, text", blocks())
def test_every_example_frames_its_subject(page, text):
    if not SCENE.search(text):
        pytest.skip("a fragment: no scene to render")
    checked = fractalc.loads(text, path=str(page.parent / "example.frac")).checked
    if checked.camera.projection == "equirectangular":
        pytest.skip("a 360-degree view has no frame")
    subject = without_ground(checked.shape)
    if subject is None:
        pytest.skip("a scene of planes alone: no subject to frame")
    image = Scene(replace(checked, shape=subject), lanes=1).render(width=WIDTH, height=HEIGHT, samples=1)
    hit = np.isfinite(image.depth)
    assert hit.mean() >= MIN_SUBJECT, f"the subject is not in view ({hit.sum()} pixels)"
    borders = {"top": hit[0].any(), "bottom": hit[-1].any(), "left": hit[:, 0].any(), "right": hit[:, -1].any()}
    assert not all(borders.values()), (
        f"the subject touches every border ({hit.mean():.0%} of the image): it is cut off, or the camera is in it")
