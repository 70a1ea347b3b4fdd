"""Bad input: one clear message naming what is wrong, from the API and from the CLI."""

import numpy as np
import pytest
import trimesh
from helpers import assert_one_line_error, box_surface, icosphere, run_cli

from hydrotact import HydrotactError
from hydrotact.field import make_laplace_problem
from hydrotact.mesh import Plane, make_box, make_tet_mesh, tetrahedralize, write_mesh

UNIT_TET = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) * 1e-3


def _open_surface():
    surface = icosphere()
    return trimesh.Trimesh(surface.vertices, surface.faces[1:], process=False)


def _self_intersecting_surface():
    first = box_surface((4e-3, 4e-3, 4e-3))
    second = box_surface((4e-3, 4e-3, 4e-3))
    second.apply_translation([2e-3, 1e-3, 1e-3])
    return trimesh.util.concatenate([first, second])


def test_non_closed_surface(tmp_path):
    with pytest.raises(HydrotactError, match="not closed"):
        tetrahedralize(_open_surface(), 1e-3)
    path = tmp_path / "open.stl"
    _open_surface().export(path)
    assert_one_line_error(run_cli("mesh", path), "open.stl", "not closed")


def test_self_intersecting_surface(tmp_path):
    with pytest.raises(HydrotactError, match="intersects itself"):
        tetrahedralize(_self_intersecting_surface(), 1e-3)
    path = tmp_path / "crossing.stl"
    _self_intersecting_surface().export(path)
    assert_one_line_error(run_cli("mesh", path), "crossing.stl", "intersects itself")


def test_clean_surfaces_are_not_reported_as_self_intersecting():
    from hydrotact.mesh import find_self_intersections, seed_surface

    for vertices, faces in (seed_surface("ellipsoid8"), (icosphere().vertices, icosphere().faces)):
        assert len(find_self_intersections(np.asarray(vertices), np.asarray(faces))) == 0


def test_zero_volume_tet(tmp_path):
    flat = UNIT_TET.copy()
    flat[3] = [0.3e-3, 0.3e-3, 0.0]
    with pytest.raises(HydrotactError, match="tet 0 is degenerate"):
        make_tet_mesh(flat, [[0, 1, 2, 3]])
    with pytest.raises(HydrotactError, match="repeats a vertex"):
        make_tet_mesh(UNIT_TET, [[0, 1, 2, 2]])
    path = tmp_path / "flat.vtu"
    _write_raw_vtu(path, flat, [[0, 1, 2, 3]])
    assert_one_line_error(run_cli("field", path), "flat.vtu", "tet 0 is degenerate")


def test_inverted_tet(tmp_path):
    with pytest.raises(HydrotactError, match="tet 0 is inverted"):
        make_tet_mesh(UNIT_TET, [[0, 2, 1, 3]])
    path = tmp_path / "inverted.vtk"
    _write_raw_vtu(path, UNIT_TET, [[0, 2, 1, 3]])
    assert_one_line_error(run_cli("field", path), "inverted.vtk", "tet 0 is inverted")


def test_no_core_faces(tmp_path):
    mesh = make_box((2e-3, 2e-3, 2e-3), 0.5e-3, bottom="free")
    with pytest.raises(HydrotactError, match="no core faces"):
        make_laplace_problem(mesh)
    with pytest.raises(HydrotactError, match="matches none"):
        tetrahedralize(box_surface(), 1e-3, core=Plane((0.0, 0.0, -1e-3)))
    path = tmp_path / "ball.stl"
    icosphere().export(path)
    assert_one_line_error(run_cli("field", path, "--core-plane", "-0.1"), "ball.stl", "no boundary face lies on the core")
    path = tmp_path / "allfree.vtu"
    write_mesh(mesh, path)
    assert_one_line_error(run_cli("field", path), "allfree.vtu", "no core faces")


def test_nan_coordinates(tmp_path):
    vertices = UNIT_TET.copy()
    vertices[2, 1] = np.nan
    with pytest.raises(HydrotactError, match="vertex 2 has a non-finite coordinate"):
        make_tet_mesh(vertices, [[0, 1, 2, 3]])
    surface = box_surface()
    surface_vertices = np.array(surface.vertices)
    surface_vertices[5, 0] = np.nan
    with pytest.raises(HydrotactError, match="vertex 5 has a non-finite coordinate"):
        tetrahedralize((surface_vertices, surface.faces), 1e-3)
    path = tmp_path / "nan.vtk"
    _write_raw_vtu(path, vertices, [[0, 1, 2, 3]])
    assert_one_line_error(run_cli("mesh", path), "nan.vtk", "non-finite")


@pytest.mark.parametrize("edge_length", [0.0, -1e-3, float("nan")])
def test_bad_edge_length(edge_length):
    with pytest.raises(HydrotactError, match="edge length must be a positive length"):
        tetrahedralize(box_surface(), edge_length)
    with pytest.raises(HydrotactError, match="edge length must be a positive length"):
        make_box((1e-3, 1e-3, 1e-3), edge_length)


def test_bad_edge_length_from_the_cli():
    assert_one_line_error(run_cli("mesh", "sphere8", "--edge-length", "0"), "edge length must be a positive length")
    assert_one_line_error(run_cli("mesh", "pad5x5", "--edge-length=-1e-3"), "edge length must be a positive length")


def test_unknown_sensor_and_missing_file():
    assert_one_line_error(run_cli("mesh", "sphere9"), "sphere9", "neither a built-in sensor")
    assert_one_line_error(run_cli("field", "pad5x5", "--modulus", "-5"), "modulus must be a positive")


def test_output_is_not_touched_on_error(tmp_path):
    """A failing run leaves an earlier good output file as it was."""
    good = tmp_path / "mesh.vtu"
    assert run_cli("mesh", "pad5x5", "--edge-length", "2e-3", "-o", good).returncode == 0
    before = good.read_bytes()
    result = run_cli("mesh", "pad5x5", "--edge-length", "0", "-o", good)
    assert result.returncode == 2
    assert good.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.vtu"]


def _write_raw_vtu(path, vertices, tets):
    """Write a mesh file without hydrotact's checks (to feed it bad meshes)."""
    import pyvista as pv

    tets = np.asarray(tets)
    cells = np.column_stack([np.full(len(tets), 4), tets]).reshape(-1)
    grid = pv.UnstructuredGrid(cells, np.full(len(tets), 10, dtype=np.uint8), np.asarray(vertices))
    grid.save(str(path), binary=False)
