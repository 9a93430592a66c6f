"""`Scene.mesh` and `fractalc mesh`: marching cubes over the kernel's
distance, in slabs, into watertight meshes and STL/PLY/OBJ files."""
import struct

import numpy as np
import pytest

import fractalc
from fractalc.cli import main
from fractalc.mesh import Grid, Mesh

pytest.importorskip("skimage.measure", reason="meshes need scikit-image (pip install 'fractalc[mesh]')")

SPHERE = "scene sphere(1)\n"


def exit_code(argv) -> int:
    """main's exit code, also for argparse's own usage errors."""
    try:
        return main(argv)
    except SystemExit as stop:
        return stop.code


def edge_uses(faces: np.ndarray) -> np.ndarray:
    """How many faces use each undirected edge."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0, return_counts=True)[1]


def directed_edges_unique(faces: np.ndarray) -> bool:
    """Consistent winding: each directed edge belongs to one face."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return len(np.unique(edges, axis=0)) == len(edges)


@pytest.fixture(scope="module")
def sphere_mesh():
    return fractalc.loads(SPHERE).mesh(resolution=128)


@pytest.mark.opencl
def test_sphere_vertices_lie_on_the_unit_sphere(sphere_mesh):
    radii = np.linalg.norm(sphere_mesh.vertices, axis=1)
    assert np.abs(radii - 1).max() < 0.01


@pytest.mark.opencl
def test_sphere_mesh_is_watertight_and_consistently_wound(sphere_mesh):
    assert np.all(edge_uses(sphere_mesh.faces) == 2)
    assert directed_edges_unique(sphere_mesh.faces)


@pytest.mark.opencl
def test_sphere_volume_within_one_percent(sphere_mesh):
    # positive: faces wind counter-clockwise seen from outside
    assert sphere_mesh.volume() == pytest.approx(4 / 3 * np.pi, rel=0.01)


@pytest.mark.opencl
def test_normals_are_the_outward_unit_gradient(sphere_mesh):
    radial = sphere_mesh.vertices / np.linalg.norm(sphere_mesh.vertices, axis=1, keepdims=True)
    assert np.allclose(np.linalg.norm(sphere_mesh.normals, axis=1), 1, atol=1e-5)
    assert np.einsum("ij,ij->i", sphere_mesh.normals, radial).min() > 0.999


@pytest.mark.opencl
def test_menger_level_2_volume():
    # Level 2 keeps (20/27)^2 of the cube [-1,1]^3. Its smallest holes are
    # 2/9 wide: 128 cells over the bound's cube (side 2 sqrt(3) * 1.02) put
    # eight cells across each. The surface meshed is half a cell out, then
    # moved back (fractalc/mesh.py); along the sponge's many edges the
    # gradient turns within a cell, so the volume comes out too large by
    # about a cell's worth along the edges: +4.6% at 64 cells, +1.2% at
    # 128, falling with the cell size. 128 takes about a second.
    mesh = fractalc.loads("scene menger(level: 2)").mesh(resolution=128)
    assert mesh.volume() == pytest.approx((20 / 27) ** 2 * 8, rel=0.02)
    assert np.all(edge_uses(mesh.faces) == 2)


@pytest.mark.opencl
def test_fractal_estimate_meshes_as_one_solid():
    # the Mandelbulb's estimate is positive at specks inside the solid: its
    # zero set alone would be a dust of small closed surfaces in there
    mesh = fractalc.loads("scene mandelbulb()\n").mesh(resolution=48)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    edges = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), edges.T), shape=(len(mesh.vertices),) * 2)
    sizes = np.bincount(connected_components(graph, directed=False)[1])
    assert sizes.max() > 0.9 * len(mesh.vertices)


# A ball with a cavity (radius 0.5) holding a smaller ball (an island in
# the void), and a loose ball beside it: four closed surfaces.
HOLLOW_BALL = ("scene union(subtract(sphere(1), sphere(0.5)), sphere(0.3), "
               "sphere(0.25).translate((1.6, 0, 0)))\n")


def ball(radius):
    return 4 / 3 * np.pi * radius ** 3


@pytest.fixture(scope="module")
def hollow_ball_mesh():
    return fractalc.loads(HOLLOW_BALL).mesh(resolution=64)


@pytest.mark.opencl
def test_shells_are_the_bodies_and_voids_with_their_volumes(hollow_ball_mesh):
    _, volumes = hollow_ball_mesh.shells()
    # sorted: the void (wound inwards: negative), the island, the loose ball, the hollow ball
    expected = [-ball(0.5), ball(0.25), ball(0.3), ball(1)]
    assert np.sort(volumes) == pytest.approx(sorted(expected), rel=0.03)


@pytest.mark.opencl
def test_solid_keeps_the_largest_body_with_its_voids_filled(hollow_ball_mesh):
    solid, removed = hollow_ball_mesh.solid()
    assert (removed.kept, removed.voids, removed.others) == (1, 1, 2)
    assert removed.void_volume == pytest.approx(ball(0.5), rel=0.03)
    assert removed.others_volume == pytest.approx(ball(0.3) + ball(0.25), rel=0.03)
    assert solid.volume() == pytest.approx(ball(1), rel=0.01)
    assert len(solid.shells()[1]) == 1 and np.all(edge_uses(solid.faces) == 2)
    assert directed_edges_unique(solid.faces)
    # only the vertices of the faces kept, with their normals
    assert np.array_equal(np.unique(solid.faces), np.arange(len(solid.vertices)))
    assert len(solid.normals) == len(solid.vertices)
    assert np.einsum("ij,ij->i", solid.normals, solid.vertices / np.linalg.norm(solid.vertices, axis=1,
                                                                                   keepdims=True)).min() > 0.99


@pytest.mark.opencl
def test_solid_with_a_minimum_volume_keeps_loose_bodies_but_not_those_inside_a_void(hollow_ball_mesh):
    # the island (0.113) is above the minimum too, but lies in the filled cavity
    solid, removed = hollow_ball_mesh.solid(min_volume=0.05)
    assert (removed.kept, removed.voids, removed.others) == (2, 1, 1)
    assert solid.volume() == pytest.approx(ball(1) + ball(0.25), rel=0.01)
    assert removed.others_volume == pytest.approx(ball(0.3), rel=0.03)


@pytest.mark.opencl
def test_the_mandelbulb_meshes_to_one_solid():
    # its mesh holds many tiny voids and specks inside them (at 128 cells:
    # 348 surfaces, 333 of them voids), which slicers flag
    raw = fractalc.loads("scene mandelbulb()\n").mesh(resolution=52)
    _, volumes = raw.shells()
    assert (volumes < 0).sum() >= 3 and (volumes > 0).sum() >= 3
    solid, removed = raw.solid()
    assert removed.voids == (volumes < 0).sum() and removed.kept == 1
    _, solid_volumes = solid.shells()
    assert len(solid_volumes) == 1 and solid_volumes[0] == pytest.approx(volumes.max(), rel=1e-9)
    assert np.all(edge_uses(solid.faces) == 2)


@pytest.mark.opencl
def test_cli_writes_stl_as_one_solid_and_other_formats_whole(tmp_path, capsys):
    scene = tmp_path / "s.frac"
    scene.write_text(HOLLOW_BALL)
    stl, ply = tmp_path / "s.stl", tmp_path / "s.ply"
    assert main(["mesh", str(scene), "-o", str(stl), "--resolution", "64"]) == 0
    said = capsys.readouterr().err
    assert "one solid: kept 1 body; filled 1 internal void" in said and "removed 2 other bodies" in said
    (count,) = struct.unpack_from("<I", stl.read_bytes(), 80)
    assert main(["mesh", str(scene), "-o", str(ply), "--resolution", "64", "-q"]) == 0
    assert capsys.readouterr().err == ""
    assert f"element face {count}".encode() not in ply.read_bytes()[:400]      # the PLY has every surface
    assert main(["mesh", str(scene), "-o", str(ply), "--resolution", "64", "--shells", "solid", "-q"]) == 0
    assert f"element face {count}".encode() in ply.read_bytes()[:400]
    assert exit_code(["mesh", str(scene), "-o", str(stl), "--shells", "all", "--min-volume", "0.1"]) == 2
    assert "--min-volume is for --shells solid" in capsys.readouterr().err


@pytest.mark.opencl
def test_slabs_weld_into_the_same_mesh_as_one_block():
    # one z-plane per kernel call against all planes in one: the seams weld,
    # so the meshes are the same vertex for vertex
    scene = fractalc.loads("scene torus(1, 0.4).rotate((1, 0, 0), 30)\n")
    from fractalc.mesh import mesh
    whole = mesh(scene, 40, chunk_points=10 ** 7)
    sliced = mesh(scene, 40, chunk_points=2000)    # a z-plane (41 x 41 points) per call
    assert len(sliced.vertices) == len(whole.vertices)
    # the same points, up to float32 rounding of the grid coordinates
    rows = [v[np.lexsort(np.round(v, 4).T)] for v in (sliced.vertices, whole.vertices)]
    assert np.allclose(*rows, rtol=0, atol=1e-5)
    assert np.all(edge_uses(sliced.faces) == 2)


@pytest.mark.opencl
def test_points_per_kernel_call_are_bounded(monkeypatch):
    # the memory bound: no call evaluates more than a chunk (one z-plane
    # when a plane is larger), whatever the resolution
    scene = fractalc.loads(SPHERE)
    calls = []
    evaluate = scene.distance
    monkeypatch.setattr(scene, "distance", lambda points: calls.append(len(points)) or evaluate(points))
    from fractalc.mesh import mesh
    mesh(scene, 60, chunk_points=61 * 61 * 3 + 5)
    assert max(calls) <= 61 * 61 * 3 + 5
    grid = Grid.over((0, 0, 0), (1, 1, 1), 1024)
    assert grid.planes_per_slab() * grid.counts[0] * grid.counts[1] <= 2 ** 21
    assert grid.counts == (1025, 1025, 1025)


@pytest.mark.opencl
def test_surface_cut_by_the_bounds_is_capped_on_them():
    # the top half of the cube [-1,1]^3: the cut at z = 0 is closed by a cap in that plane
    mesh = fractalc.loads("scene box(2)\n").mesh(resolution=40, bounds=(-2, -2, 0, 2, 2, 2))
    assert np.all(edge_uses(mesh.faces) == 2)
    assert mesh.vertices[:, 2].min() == pytest.approx(0, abs=1e-6)
    assert mesh.volume() == pytest.approx(4.0, rel=0.01)


def test_unbounded_scene_needs_bounds():
    scene = fractalc.loads("scene union(sphere(1), plane(offset: -1))\n")
    with pytest.raises(ValueError, match="unbounded"):
        scene.mesh(resolution=16)
    with pytest.raises(ValueError, match="minimum must be less"):
        scene.mesh(resolution=16, bounds=(0, 0, 0, 1, -1, 1))


@pytest.mark.opencl
def test_no_surface_in_bounds_is_an_error():
    with pytest.raises(ValueError, match="no surface"):
        fractalc.loads(SPHERE).mesh(resolution=8, bounds=(2, 2, 2, 3, 3, 3))


@pytest.fixture(scope="module")
def small_mesh():
    return fractalc.loads(SPHERE).mesh(resolution=12)


@pytest.mark.opencl
def test_stl_file_holds_every_triangle(small_mesh, tmp_path):
    path = tmp_path / "sphere.stl"
    small_mesh.save(str(path))
    data = path.read_bytes()
    (count,) = struct.unpack_from("<I", data, 80)
    assert count == len(small_mesh.faces) and len(data) == 84 + 50 * count
    record = np.frombuffer(data, dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")], offset=84)
    assert np.array_equal(record["v"], small_mesh.vertices[small_mesh.faces])


@pytest.mark.opencl
def test_ply_file_round_trips(small_mesh, tmp_path):
    path = tmp_path / "sphere.ply"
    small_mesh.save(str(path))
    data = path.read_bytes()
    header, body = data.split(b"end_header\n", 1)
    assert f"element vertex {len(small_mesh.vertices)}".encode() in header
    vertices = np.frombuffer(body, "<f4", count=6 * len(small_mesh.vertices)).reshape(-1, 6)
    faces = np.frombuffer(body, [("n", "u1"), ("i", "<i4", 3)], offset=vertices.nbytes)
    assert np.array_equal(vertices[:, :3], small_mesh.vertices)
    assert np.array_equal(vertices[:, 3:], small_mesh.normals)
    assert np.all(faces["n"] == 3) and np.array_equal(faces["i"], small_mesh.faces)


@pytest.mark.opencl
def test_obj_file_round_trips(small_mesh, tmp_path):
    path = tmp_path / "sphere.obj"
    small_mesh.save(str(path))
    lines = path.read_text().splitlines()
    vertices = np.array([line.split()[1:] for line in lines if line.startswith("v ")], float)
    faces = [line.split()[1:] for line in lines if line.startswith("f ")]
    assert np.allclose(vertices, small_mesh.vertices, atol=1e-6)
    assert np.array_equal(np.array([[int(c.split("//")[0]) - 1 for c in f] for f in faces]), small_mesh.faces)


@pytest.mark.opencl
def test_unknown_extension_is_refused(small_mesh, tmp_path):
    with pytest.raises(ValueError, match=".stl"):
        small_mesh.save(str(tmp_path / "sphere.dae"))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.opencl
def test_cli_writes_a_mesh(tmp_path, capsys):
    scene = tmp_path / "s.frac"
    scene.write_text(SPHERE)
    out = tmp_path / "s.stl"
    assert main(["mesh", str(scene), "-o", str(out), "--resolution", "16", "-q"]) == 0
    (count,) = struct.unpack_from("<I", out.read_bytes(), 80)
    assert count > 100


@pytest.mark.parametrize("args, message", [
    (["-o", "OUT.dae"], "-o OUT.dae: the output must end in one of .stl, .ply, .obj"),
    (["-o", "OUT.stl", "--resolution", "1"], "argument --resolution: must be between 2 and 16384, not 1"),
    (["-o", "OUT.stl", "--bounds", "1,2,3"], "--bounds: '1,2,3' is not six numbers"),
    (["-o", "OUT.stl", "--bounds=0,0,0,1,1,0"], "each minimum must be less than its maximum"),
])
def test_cli_usage_errors(tmp_path, capsys, args, message):
    scene = tmp_path / "s.frac"
    scene.write_text(SPHERE)
    args = [a.replace("OUT", str(tmp_path / "out")) for a in args]
    message = message.replace("OUT", str(tmp_path / "out"))
    assert exit_code(["mesh", str(scene), *args]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [scene]


def test_cli_unbounded_scene_is_a_usage_error_naming_bounds(tmp_path, capsys):
    scene = tmp_path / "u.frac"
    scene.write_text("scene union(sphere(1), plane(offset: -1))\n")
    assert main(["mesh", str(scene), "-o", str(tmp_path / "u.stl")]) == 2
    err = capsys.readouterr().err
    assert "unbounded" in err and "--bounds" in err and "Traceback" not in err


def test_cli_missing_scikit_image_fails_before_any_work(tmp_path, capsys, monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "skimage.measure", None)   # import fails
    scene = tmp_path / "s.frac"
    scene.write_text("scene sphere(\n")      # not even parsed: the extra is checked first
    assert main(["mesh", str(scene), "-o", str(tmp_path / "s.stl")]) == 2
    assert "pip install 'fractalc[mesh]'" in capsys.readouterr().err


def test_mesh_repr_is_short():
    mesh = Mesh(np.zeros((3, 3), np.float32), np.array([[0, 1, 2]], np.int32), np.zeros((3, 3), np.float32))
    assert repr(mesh) == "<Mesh 3 vertices, 1 faces>"
