"""`fractalc mesh`: the scene's surface as a triangle mesh (STL, PLY, OBJ).

The distance estimate is sampled by the compiled kernel on a grid over the
scene's bounding box, a few z-planes at a time, so that memory stays
bounded whatever the resolution (only the mesh itself grows with it).
Each slab of planes goes through scikit-image's marching cubes; slabs share
their boundary plane, whose vertices are welded to the previous slab's.
The grid is surrounded by samples outside the surface, so a surface cut by
the bounds is closed by a cap there: the mesh is always watertight. Vertex
normals are the kernel's gradient by central differences.

The level meshed is half a cell out, not 0: a fractal's estimate (the
Mandelbulb's 0.5 log(r) r / dr) is not negative everywhere inside, only
small, so its zero set is a dust of specks inside the solid, while the
set within half a cell of it is the one solid a ray marcher sees. Each
vertex is then moved back by half a cell against its normal, onto the
surface for a true distance and never past it for an estimate, which
only underestimates the distance.
"""
from __future__ import annotations

import enum
import math
import sys
from dataclasses import dataclass

import numpy as np

from .arguments import MAX_RESOLUTION, checked
from .transforms import MAX_COORDINATE
from .memory import require_memory
from .write import replacing

FORMATS = (".stl", ".ply", ".obj")
PRINTING_FORMATS = (".stl",)    # read by slicers, which want one solid
INSTALL_HINT = "meshes need scikit-image: pip install 'fractalc[mesh]'"
CHUNK_POINTS = 1 << 21   # distance evaluations per kernel call: ~100 MB of host arrays at most
DEFAULT_RESOLUTION = 256
LEVEL_CELLS = 0.5    # the level meshed, in cells (see above)
# A cell at least this fraction of the box's largest coordinate: its
# corners, and the normals' differences a quarter of a cell wide, stay
# apart by 2^6 units of the last place of the kernel's numbers
CELL_PRECISION = {False: 2.0 ** -17, True: 2.0 ** -46}     # double?
# Memory of sampling (Grid.sampling_bytes): the slab, the plane kept and
# marching cubes' arrays come to about SLAB_COPIES slabs; a chunk of points
# costs CHUNK_POINT_BYTES a point (xyz and their meshgrid in float64, the
# distances). Measured (benchmarks/mesh_memory.py's way, a sphere of 0.01
# in a slab of the box): 2048^2 planes 272 MiB over the interpreter's, 4096^2
# 465 MiB, against 294 MB and 700 MB estimated.
SLAB_COPIES = 4
CHUNK_POINT_BYTES = 80


def require_scikit_image() -> None:
    """Fail before any work if marching cubes is not installed."""
    try:
        import skimage.measure  # noqa: F401
    except ImportError:
        raise ImportError(INSTALL_HINT) from None


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh: (V, 3) float32 vertices, (F, 3) int32 faces
    (counter-clockwise seen from outside) and (V, 3) float32 unit normals."""
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray

    def __repr__(self) -> str:
        return f"<Mesh {len(self.vertices)} vertices, {len(self.faces)} faces>"

    def volume(self) -> float:
        """The enclosed volume (divergence theorem; exact for a closed mesh)."""
        return float(self._face_volumes().sum())

    def _face_volumes(self) -> np.ndarray:
        """Each face's share of the enclosed volume (the signed volume of
        the tetrahedron it spans with the origin)."""
        a, b, c = (self.vertices[self.faces[:, i]].astype(np.float64) for i in range(3))
        return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0

    def shells(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh's closed surfaces: each face's shell number, and each
        shell's signed volume: > 0 for a body (wound counter-clockwise seen
        from outside), < 0 for a void inside one (its surface faces in)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        edges = np.concatenate([self.faces[:, [0, 1]], self.faces[:, [1, 2]]])
        graph = coo_matrix((np.ones(len(edges), np.int8), edges.T.astype(np.int64)), shape=(len(self.vertices),) * 2)
        count, of_vertex = connected_components(graph, directed=False)
        of_face = of_vertex[self.faces[:, 0]]
        volumes = np.bincount(of_face, self._face_volumes(), minlength=count)
        used = np.bincount(of_face, minlength=count) > 0      # (vertices of no face make empty components)
        renumber = np.cumsum(used) - 1
        return renumber[of_face], volumes[used]

    def solid(self, min_volume: float | None = None) -> tuple["Mesh", "ShellsRemoved"]:
        """The mesh as one solid for printing: its largest body (or every
        body of at least `min_volume` that lies outside the others), with
        every internal void filled (its surface removed) and the other
        bodies (loose specks, bodies inside the voids) removed; and what was
        removed."""
        of_face, volumes = self.shells()
        bodies = np.flatnonzero(volumes > 0)
        if len(bodies) == 0:
            return self, ShellsRemoved(0, 0, 0, 0.0, 0.0)
        largest = bodies[np.argmax(volumes[bodies])]
        kept = [largest]
        if min_volume is not None:
            others = [b for b in bodies[np.argsort(-volumes[bodies])] if b != largest and volumes[b] >= min_volume]
            for body in others:
                # a body inside a kept one lies in a void of it, which is filled
                point = self.vertices[self.faces[of_face == body][0, 0]].astype(np.float64)
                if not any(_encloses(self.vertices[self.faces[of_face == k]].astype(np.float64), point)
                           for k in kept):
                    kept.append(body)
        keep = np.isin(of_face, kept)
        voids = volumes < 0
        others = np.ones(len(volumes), bool)
        others[kept] = False
        others &= ~voids
        removed = ShellsRemoved(len(kept), int(voids.sum()), int(others.sum()),
                                float(-volumes[voids].sum()), float(volumes[others].sum()))
        faces = self.faces[keep]
        used = np.zeros(len(self.vertices), bool)
        used[faces.ravel()] = True
        renumber = (np.cumsum(used) - 1).astype(np.int32)
        return Mesh(self.vertices[used], renumber[faces], self.normals[used]), removed

    def save(self, path: str) -> None:
        """Write binary STL, binary PLY or OBJ (by the extension), atomically."""
        writer = _WRITERS.get(_extension(path))
        if writer is None:
            raise ValueError(f"a mesh is written as {', '.join(FORMATS)}, not {path}")
        with replacing(path) as temporary, open(temporary, "wb") as f:
            writer(self, f)


class Shells(enum.Enum):
    """What `fractalc mesh` writes: every closed surface the grid holds, or
    one solid (`Mesh.solid`)."""
    ALL = "all"
    SOLID = "solid"

    @staticmethod
    def default_for(path: str) -> "Shells":
        """One solid for the formats printers read, everything otherwise."""
        return Shells.SOLID if _extension(path) in PRINTING_FORMATS else Shells.ALL


@dataclass(frozen=True)
class ShellsRemoved:
    """What `Mesh.solid` kept and removed."""
    kept: int             # bodies kept
    voids: int            # internal voids filled
    others: int           # the other bodies, removed: loose specks, bodies inside voids
    void_volume: float    # the volume the filled voids add
    others_volume: float  # the volume of the bodies removed

    def summary(self) -> str:
        if not self.voids and not self.others:
            return f"one solid: {self.kept} {_plural(self.kept, 'body', 'bodies')}, nothing removed"
        return (f"one solid: kept {self.kept} {_plural(self.kept, 'body', 'bodies')}; filled "
                f"{self.voids} internal {_plural(self.voids, 'void', 'voids')} (volume {self.void_volume:.3g}), "
                f"removed {self.others} other {_plural(self.others, 'body', 'bodies')} "
                f"(volume {self.others_volume:.3g})")


def _plural(count: int, one: str, many: str) -> str:
    return one if count == 1 else many


def _encloses(corners: np.ndarray, point: np.ndarray) -> bool:
    """Whether the closed surface of (F, 3, 3) triangles encloses `point`:
    a ray from it crosses the surface an odd number of times (Moeller and
    Trumbore's ray-triangle test; the ray's direction is generic, so that
    it meets no edge or vertex of a grid-aligned mesh)."""
    direction = np.array([1.0, 0.0123, 0.0456])
    a, ab, ac = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    across = np.cross(direction, ac)
    determinant = np.einsum("ij,ij->i", ab, across)
    safe = np.where(determinant != 0, determinant, 1.0)
    offset = point - a
    u = np.einsum("ij,ij->i", offset, across) / safe
    turned = np.cross(offset, ab)
    v = (turned @ direction) / safe
    t = np.einsum("ij,ij->i", ac, turned) / safe
    crossing = (determinant != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return bool(np.count_nonzero(crossing) % 2)


def _extension(path: str) -> str:
    return "." + path.rsplit(".", 1)[-1].lower() if "." in path else ""


def _face_normals(corners: np.ndarray) -> np.ndarray:
    """Unit normals of (F, 3, 3) triangles (0 for a degenerate one)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)


WRITE_FACES = 1 << 20    # faces (or vertices) per block written: a copy of the whole mesh would double its memory


def _write_stl(mesh: Mesh, f) -> None:
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    f.write(b"fractalc binary STL".ljust(80, b" "))
    f.write(np.uint32(len(mesh.faces)).tobytes())
    for start in range(0, len(mesh.faces), WRITE_FACES):
        faces = mesh.faces[start:start + WRITE_FACES]
        triangles = np.zeros(len(faces), dtype=record)
        triangles["corners"] = mesh.vertices[faces]
        triangles["normal"] = _face_normals(triangles["corners"])
        f.write(triangles)


def _write_ply(mesh: Mesh, f) -> None:
    f.write((f"ply\nformat binary_little_endian 1.0\ncomment made by fractalc\n"
             f"element vertex {len(mesh.vertices)}\n"
             "property float x\nproperty float y\nproperty float z\n"
             "property float nx\nproperty float ny\nproperty float nz\n"
             f"element face {len(mesh.faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
    for start in range(0, len(mesh.vertices), WRITE_FACES):
        block = np.empty((len(mesh.vertices[start:start + WRITE_FACES]), 6), "<f4")
        block[:, :3] = mesh.vertices[start:start + WRITE_FACES]
        block[:, 3:] = mesh.normals[start:start + WRITE_FACES]
        f.write(block)
    for start in range(0, len(mesh.faces), WRITE_FACES):
        block = mesh.faces[start:start + WRITE_FACES]
        faces = np.zeros(len(block), dtype=[("count", "u1"), ("indices", "<i4", 3)])
        faces["count"] = 3
        faces["indices"] = block
        f.write(faces)


def _write_obj(mesh: Mesh, f) -> None:
    f.write(b"# made by fractalc\n")
    np.savetxt(f, mesh.vertices, fmt="v %.7g %.7g %.7g")
    np.savetxt(f, mesh.normals, fmt="vn %.6g %.6g %.6g")
    corners = np.repeat(mesh.faces + 1, 2, axis=1)    # OBJ counts from 1; each corner is v//vn
    np.savetxt(f, corners, fmt="f %d//%d %d//%d %d//%d")


_WRITERS = {".stl": _write_stl, ".ply": _write_ply, ".obj": _write_obj}


@dataclass(frozen=True)
class Grid:
    """The sample points: lower + spacing * (i, j, k) for i < counts[0], ..."""
    lower: np.ndarray
    spacing: float
    counts: tuple[int, int, int]

    @staticmethod
    def over(lower, upper, resolution: int) -> "Grid":
        """`resolution` cells along the box's longest side, as many of the
        same size as cover each other side."""
        lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
        spacing = float(np.max(upper - lower)) / resolution
        counts = tuple(int(math.ceil((u - l) / spacing - 1e-9)) + 1 for l, u in zip(lower, upper))
        return Grid(lower, spacing, counts)

    @property
    def upper(self) -> np.ndarray:
        return self.lower + self.spacing * np.subtract(self.counts, 1)

    def planes_per_slab(self, chunk_points: int = CHUNK_POINTS) -> int:
        """z-planes meshed at a time: as many as fit in a chunk, at least one."""
        return max(1, chunk_points // (self.counts[0] * self.counts[1]))

    def rows_per_call(self, chunk_points: int = CHUNK_POINTS) -> int:
        """y-rows of a plane evaluated per kernel call, where a whole plane
        is more than a chunk."""
        return max(1, min(self.counts[1], chunk_points // self.counts[0]))

    def plane_points(self, first: int, count: int, row: int = 0, rows: int | None = None) -> np.ndarray:
        """The (count * rows * nx, 3) points of z-planes first..first+count-1,
        rows `row`.. `row + rows - 1` of each (default: all), x varying fastest."""
        nx, ny, _ = self.counts
        rows = ny - row if rows is None else rows
        x = self.lower[0] + self.spacing * np.arange(nx)
        y = self.lower[1] + self.spacing * np.arange(row, row + rows)
        z = self.lower[2] + self.spacing * np.arange(first, first + count)
        zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
        return np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1)

    def sampling_bytes(self, chunk_points: int = CHUNK_POINTS) -> int:
        """The memory sampling takes besides the mesh: a padded slab, the
        plane kept from the slab before, marching cubes' work arrays on the
        slab (SLAB_COPIES in all) and a chunk of points (float64 xyz, their
        meshgrid, the distances)."""
        nx, ny, _ = self.counts
        slab = (nx + 2) * (ny + 2) * (self.planes_per_slab(chunk_points) + 1) * 4
        return SLAB_COPIES * slab + chunk_points * CHUNK_POINT_BYTES


def check_bounds(bounds, resolution: int, double: bool, name: str = "bounds") -> tuple[np.ndarray, np.ndarray]:
    """`bounds` (xmin, ymin, zmin, xmax, ymax, zmax) as (lower, upper);
    ValueError, of `name`, where its cells would be degenerate: a side shorter than
    one cell (longest side / `resolution`), a coordinate beyond
    transforms.MAX_COORDINATE (where the kernel clamps points), or cells too
    small for the kernel's numbers to tell their corners apart there
    (CELL_PRECISION: float's or double's)."""
    try:
        values = np.array([float(v) for v in bounds], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be six numbers xmin, ymin, zmin, xmax, ymax, zmax, not {bounds!r}") from None
    if values.shape != (6,) or not np.all(np.isfinite(values)):
        raise ValueError(f"{name} must be six finite numbers: xmin, ymin, zmin, xmax, ymax, zmax")
    lower, upper = values[:3], values[3:]
    if not np.all(lower < upper):
        raise ValueError(f"{name}: each minimum must be less than its maximum")
    if np.max(np.abs(values)) > MAX_COORDINATE:
        raise ValueError(f"{name}: coordinates must lie within ±{MAX_COORDINATE:g}, where the kernel's points do")
    sides = upper - lower
    cell = float(np.max(sides)) / resolution
    if np.min(sides) < cell:
        axis, needed = "xyz"[int(np.argmin(sides))], math.ceil(np.max(sides) / np.min(sides))
        raise ValueError(f"{name}: the box's {axis} side ({np.min(sides):g}) is shorter than one cell "
                         f"({cell:g}, the longest side / resolution {resolution}); widen the box"
                         + (f" or raise the resolution to {needed} or more" if needed <= MAX_RESOLUTION else ""))
    largest = float(np.max(np.abs(values)))
    if cell < largest * CELL_PRECISION[double]:
        raise ValueError(f"{name}: cells of {cell:g} are too small for {'double' if double else 'float'} numbers "
                         f"at coordinates up to {largest:g} (a cell must be at least "
                         f"{largest * CELL_PRECISION[double]:.3g} there); a box nearer the origin or fewer cells"
                         + ("" if double else ", or double precision"))
    return lower, upper


def bounds_of(scene, bounds=None, resolution: int = DEFAULT_RESOLUTION,
              name: str = "bounds") -> tuple[np.ndarray, np.ndarray]:
    """The box to mesh: `bounds` (xmin, ymin, zmin, xmax, ymax, zmax; see
    check_bounds), else the cube around the scene's bounding sphere, a
    little larger."""
    if bounds is not None:
        return check_bounds(bounds, resolution, scene.precision == "double", name)
    sphere = scene.bound()     # None for a ground plane, repetition or a warp
    if sphere is None:
        raise ValueError(f"{scene.checked.file} is unbounded (a plane, repetition or warp): "
                         "give the bounds of the part to mesh")
    centre, radius = np.asarray(sphere[0], np.float64), sphere[1]
    radius *= 1.02     # the surface never touches the grid's edge
    return centre - radius, centre + radius


def mesh(scene, resolution: int = DEFAULT_RESOLUTION, bounds=None, progress: bool = False,
         chunk_points: int = CHUNK_POINTS) -> Mesh:
    """The scene's surface (distance 0) as a watertight mesh, from the
    distance estimate on a grid of `resolution` cells along the longest
    side of `bounds` (default: the scene's bound)."""
    require_scikit_image()
    resolution = checked("resolution", resolution)
    grid = Grid.over(*bounds_of(scene, bounds, resolution), resolution)
    require_memory(grid.sampling_bytes(chunk_points),
                   f"meshing at resolution {resolution} ({' x '.join(map(str, grid.counts))} samples)")
    level = grid.spacing * LEVEL_CELLS
    vertices, faces = _march(scene, grid, level, progress, chunk_points)
    normals = _normals(scene, vertices, grid.spacing, chunk_points)
    # back onto the surface; a cap between the padding and the grid's edge goes onto the edge
    for start in range(0, len(vertices), chunk_points):     # in blocks: no mesh-sized temporaries
        block = vertices[start:start + chunk_points]
        block -= np.float32(level) * normals[start:start + chunk_points]
        np.clip(block, grid.lower.astype(np.float32), grid.upper.astype(np.float32), out=block)
    return Mesh(vertices, faces, normals)


def _march(scene, grid: Grid, level: float, progress: bool, chunk_points: int) -> tuple[np.ndarray, np.ndarray]:
    from skimage.measure import marching_cubes
    from tqdm import tqdm
    nx, ny, nz = grid.counts
    step = grid.planes_per_slab(chunk_points)
    outside = np.float32(2 * level)   # the padding around the grid: outside the surface
    previous = np.full((nx + 2, ny + 2, 1), outside, np.float32)   # padded plane 0, below the grid
    vertex_parts, face_parts = [], []
    vertex_count, seam = 0, None      # seam: the previous slab's top-plane vertices (keys, indices)
    bar = tqdm(total=nz, unit="plane", leave=False, desc="meshing",
               disable=not (progress and sys.stderr.isatty()))
    try:
        # padded planes: 0 and nz + 1 are the padding, 1..nz the grid's planes 0..nz-1;
        # a slab is padded planes first..last, sharing plane `first` with the slab before
        for first in range(0, nz + 1, step):
            last = min(first + step, nz + 1)
            slab = np.full((nx + 2, ny + 2, last - first + 1), outside, np.float32)
            slab[..., :1] = previous
            count = min(last, nz) - first
            rows = grid.rows_per_call(chunk_points) if count == 1 else ny
            for row in range(0, ny if count > 0 else 0, rows):
                part = min(rows, ny - row)
                values = scene.distance(grid.plane_points(first, count, row, part)).astype(np.float32)
                slab[1:-1, 1 + row:1 + row + part, 1:count + 1] = values.reshape(count, part, nx).transpose(2, 1, 0)
            previous = slab[..., -1:].copy()
            bar.update(max(count, 0))
            crossing = slab.min() < level < slab.max()
            if not crossing:
                seam = None
                continue
            verts, faces, seam = _slab_mesh(marching_cubes(slab, level, gradient_direction="descent",
                                                           allow_degenerate=False)[:2],
                                            slab.shape[2] - 1, seam, vertex_count)
            verts[:, 2] += first - 1      # padded plane index to grid plane index
            vertex_parts.append(verts.astype(np.float32))   # grid units: float32 is exact to 1e-4 cell
            face_parts.append(faces.astype(np.int32))
            vertex_count += len(verts)
    finally:
        bar.close()
    if not vertex_parts:
        raise ValueError("no surface inside the bounds (the distance is on one side of the surface everywhere)")
    # padded indices: sample (i, j) is at padded (i + 1, j + 1)
    vertices = np.concatenate(vertex_parts)
    del vertex_parts[:]
    vertices -= np.float32([1, 1, 0])
    vertices *= np.float32(grid.spacing)
    vertices += grid.lower.astype(np.float32)
    faces = np.concatenate(face_parts)
    del face_parts[:]
    return vertices, faces


def _slab_mesh(marched, top_plane: int, seam, vertex_count: int):
    """A slab's new vertices (those not on the previous slab's top plane)
    and its faces, numbered after the `vertex_count` vertices before it;
    and the seam for the next slab: its top-plane vertices' (x, y) keys,
    sorted, and their numbers."""
    verts, triangles = marched
    index = np.full(len(verts), -1, dtype=np.int64)
    bottom = np.flatnonzero(verts[:, 2] == 0)
    if seam is not None and len(bottom):
        keys, numbers = seam
        wanted = _plane_keys(verts[bottom])
        found = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
        matched = keys[found] == wanted
        index[bottom[matched]] = numbers[found[matched]]
    new = index < 0
    index[new] = vertex_count + np.arange(np.count_nonzero(new))
    top = np.flatnonzero(verts[:, 2] == top_plane)
    keys = _plane_keys(verts[top])
    order = np.argsort(keys)
    return verts[new].astype(np.float64), index[triangles], (keys[order], index[top][order])


def _plane_keys(points: np.ndarray) -> np.ndarray:
    """One sortable number per (x, y) on a plane (x + iy: complex numbers
    sort by real part, then imaginary): equal for the same vertex found
    from either slab (the same edge between the same two samples)."""
    return points[:, 0].astype(np.float64) + 1j * points[:, 1].astype(np.float64)


def _normals(scene, vertices: np.ndarray, spacing: float, chunk_points: int) -> np.ndarray:
    """The gradient of the distance at each vertex (central differences a
    quarter of a cell wide), normalised."""
    offsets = np.vstack([np.eye(3), -np.eye(3)]) * (spacing / 4)
    normals = np.empty_like(vertices)
    per_chunk = max(1, chunk_points // len(offsets))
    for start in range(0, len(vertices), per_chunk):
        block = vertices[start:start + per_chunk].astype(np.float64)
        values = scene.distance((block[None, :, :] + offsets[:, None, :]).reshape(-1, 3))
        values = values.reshape(len(offsets), len(block))
        gradient = (values[:3] - values[3:]).T
        length = np.linalg.norm(gradient, axis=1, keepdims=True)
        normals[start:start + per_chunk] = gradient / np.where(length > 0, length, 1.0)
    return normals
