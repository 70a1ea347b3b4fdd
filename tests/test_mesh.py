"""Meshes: structured builders, seed sensors, fTetWild, tagging, quality, I/O."""

import json

import numpy as np
import pytest
import trimesh
from helpers import box_surface, icosphere

from hydrotact.mesh import (
    CORE,
    FREE,
    INSULATED,
    SEED_SENSORS,
    Plane,
    calc_mesh_quality,
    calc_signed_volumes,
    make_box,
    make_seed_mesh,
    make_spherical_shell,
    make_truncated_ellipsoid_surface,
    read_mesh,
    tetrahedralize,
    write_mesh,
)


def _check_outward(mesh):
    """Every boundary face's normal points away from its tet's fourth vertex."""
    vertices = np.asarray(mesh.vertices)
    faces = np.asarray(mesh.boundary_faces)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    centroid = vertices.mean(axis=0)
    # For a convex body every outward normal points away from the centroid.
    return np.einsum("ij,ij->i", normals, (a + b + c) / 3 - centroid)


def test_box_counts_orientation_and_tags():
    mesh = make_box((4e-3, 2e-3, 1e-3), 0.5e-3)
    nx, ny, nz = 8, 4, 2
    assert mesh.num_tets == 6 * nx * ny * nz
    assert mesh.num_vertices == (nx + 1) * (ny + 1) * (nz + 1)
    assert np.all(calc_signed_volumes(np.asarray(mesh.vertices), np.asarray(mesh.tets)) > 0)
    np.testing.assert_allclose(calc_signed_volumes(np.asarray(mesh.vertices), np.asarray(mesh.tets)).sum(), 8e-9, rtol=1e-12)
    assert mesh.num_faces == 2 * 2 * (nx * ny + ny * nz + nx * nz)
    assert np.all(_check_outward(mesh) > 0)
    tags = np.asarray(mesh.face_tags)
    assert np.sum(tags == CORE) == 2 * nx * ny
    core_z = np.asarray(mesh.vertices)[mesh.faces_tagged(CORE)][..., 2]
    np.testing.assert_array_equal(core_z, 0.0)
    insulated = make_box((4e-3, 2e-3, 1e-3), 0.5e-3, sides="insulated")
    assert np.sum(np.asarray(insulated.face_tags) == INSULATED) == 2 * 2 * (ny * nz + nx * nz)


def test_shell_converges_to_the_sphere_volume():
    exact = 4 / 3 * np.pi * (1.0 - 0.5**3)
    errors = [exact - calc_mesh_quality(make_spherical_shell(0.5, 1.0, n))["volume_m3"] for n in (1, 2, 4)]
    assert all(e > 0 for e in errors)  # inscribed polyhedra
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 1.8), orders
    quality = calc_mesh_quality(make_spherical_shell(0.5, 1.0, 3))
    assert quality["min_dihedral_deg"] > 20 and quality["worst_aspect_ratio"] < 2.0


@pytest.mark.parametrize("name", sorted(SEED_SENSORS))
def test_seed_meshes(name):
    mesh = make_seed_mesh(name)
    quality = calc_mesh_quality(mesh)
    spec = SEED_SENSORS[name]
    vertices = np.asarray(mesh.vertices)
    assert np.all(calc_signed_volumes(vertices, np.asarray(mesh.tets)) > 0)
    # The core is the flat base on the PCB plane, exactly at z = 0.
    core = vertices[mesh.faces_tagged(CORE)]
    np.testing.assert_array_equal(core[..., 2], 0.0)
    assert quality["num_core_faces"] > 0 and quality["num_free_faces"] > 0
    np.testing.assert_allclose(vertices[:, 2].min(), 0.0, atol=0)
    if spec["shape"] == "box":
        sx, sy, sz = spec["size_m"]
        np.testing.assert_allclose(quality["volume_m3"], sx * sy * sz, rtol=1e-12)
        np.testing.assert_allclose(quality["core_area_m2"], sx * sy, rtol=1e-12)
    else:
        a, b, c = spec["semi_axes_m"]
        h = spec["center_height_m"]
        # Volume of the ellipsoid above z = 0: integrate the cross-sections.
        z = np.linspace(-h, c, 20001)
        exact_volume = np.trapezoid(np.pi * a * b * (1 - (z / c) ** 2), z)
        np.testing.assert_allclose(quality["volume_m3"], exact_volume, rtol=5e-3)
        np.testing.assert_allclose(quality["core_area_m2"], np.pi * a * b * (1 - (h / c) ** 2), rtol=5e-3)
        assert quality["min_dihedral_deg"] > 5.0
        np.testing.assert_allclose(vertices[:, 2].max(), h + c, rtol=2e-3)


def test_seed_mesh_is_reproducible():
    first, second = make_seed_mesh("sphere8"), make_seed_mesh("sphere8")
    np.testing.assert_array_equal(np.asarray(first.vertices), np.asarray(second.vertices))
    np.testing.assert_array_equal(np.asarray(first.tets), np.asarray(second.tets))


def test_truncated_ellipsoid_surface_is_closed_and_outward():
    vertices, faces = make_truncated_ellipsoid_surface((10.7e-3, 9e-3, 6.8e-3), 3.4e-3, num_rings=24)
    surface = trimesh.Trimesh(vertices, faces, process=False)
    assert surface.is_watertight and surface.is_winding_consistent and surface.volume > 0


def test_tetrahedralize_plane_core_and_cache():
    surface = box_surface()
    mesh = tetrahedralize(surface, 1e-3, core=Plane((0.0, 0.0, 0.0)))
    quality = calc_mesh_quality(mesh)
    np.testing.assert_allclose(quality["volume_m3"], 6e-3 * 6e-3 * 3e-3, rtol=1e-3)
    np.testing.assert_allclose(quality["core_area_m2"], 36e-6, rtol=1e-3)
    again = tetrahedralize(surface, 1e-3, core=Plane((0.0, 0.0, 0.0)))
    np.testing.assert_array_equal(np.asarray(mesh.tets), np.asarray(again.tets))
    np.testing.assert_array_equal(np.asarray(mesh.vertices), np.asarray(again.vertices))


def test_tetrahedralize_face_set_and_predicate_cores():
    surface = box_surface()
    bottom = np.flatnonzero(surface.triangles_center[:, 2] < 1e-9)
    by_faces = tetrahedralize(surface, 1e-3, core=bottom)
    by_predicate = tetrahedralize(surface, 1e-3, core=lambda centroids: centroids[:, 2] < 1e-5)
    for mesh in (by_faces, by_predicate):
        core = np.asarray(mesh.vertices)[mesh.faces_tagged(CORE)]
        assert np.all(np.abs(core[..., 2]) < 1e-5)
        np.testing.assert_allclose(calc_mesh_quality(mesh)["core_area_m2"], 36e-6, rtol=1e-3)
    np.testing.assert_array_equal(np.asarray(by_faces.face_tags), np.asarray(by_predicate.face_tags))


def test_tetrahedralize_sphere_without_core_is_all_free():
    mesh = tetrahedralize(icosphere(), 1.5e-3)
    assert np.all(np.asarray(mesh.face_tags) == FREE)
    np.testing.assert_allclose(calc_mesh_quality(mesh)["volume_m3"], icosphere().volume, rtol=2e-3)


def test_quality_report_of_a_regular_tet():
    from hydrotact.mesh import make_tet_mesh

    vertices = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    mesh = make_tet_mesh(vertices, [[0, 1, 2, 3]] if calc_signed_volumes(vertices, np.array([[0, 1, 2, 3]]))[0] > 0 else [[0, 2, 1, 3]])
    quality = calc_mesh_quality(mesh)
    np.testing.assert_allclose(quality["min_dihedral_deg"], np.degrees(np.arccos(1 / 3)), rtol=1e-12)
    np.testing.assert_allclose(quality["worst_aspect_ratio"], 1.0, rtol=1e-12)
    np.testing.assert_allclose(quality["volume_m3"], 8 / 3, rtol=1e-12)
    assert quality["num_boundary_faces"] == 4


def test_vtu_round_trip_keeps_tags_and_fields(tmp_path):
    mesh = make_seed_mesh("ellipsoid8")
    strain = np.linspace(0, 1, mesh.num_vertices)
    path = write_mesh(mesh, tmp_path / "e.vtu", point_data={"strain": strain})
    back, data = read_mesh(path)
    np.testing.assert_array_equal(np.asarray(back.vertices), np.asarray(mesh.vertices))
    np.testing.assert_array_equal(np.asarray(back.tets), np.asarray(mesh.tets))
    np.testing.assert_array_equal(np.asarray(back.face_tags), np.asarray(mesh.face_tags))
    np.testing.assert_array_equal(data["strain"], strain)


def test_legacy_vtk_is_ascii_and_exact(tmp_path):
    mesh = make_seed_mesh("pad5x5", 1e-3)
    path = write_mesh(mesh, tmp_path / "pad.vtk")
    text = path.read_text()
    assert text.startswith("# vtk DataFile") and "ASCII" in text.splitlines()[2]
    back, _ = read_mesh(path)  # no tags stored: the core is the lowest plane
    np.testing.assert_allclose(np.asarray(back.vertices), np.asarray(mesh.vertices), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(back.tets), np.asarray(mesh.tets))
    np.testing.assert_array_equal(np.asarray(back.face_tags), np.asarray(mesh.face_tags))


def test_quality_json_serialisable():
    json.dumps(calc_mesh_quality(make_seed_mesh("pad5x5", 1e-3)))


# A tray (mm): the box [0,10]x[0,8]x[0,6] less the cavity [2,8]x[2,6]x[2,6], open at the
# top, with a 1 mm³ pocket former standing on its floor and a groove round the outside
# (a second, smaller hollow of the hull less the mould, which is not the cavity).
TRAY = dict(outer=((0, 0, 0), (10, 8, 6)), hollows=[((2, 2, 2), (8, 6, 6.5)), ((0, 0, 0), (1, 8, 1))], formers=[((4, 3, 2), (5, 4, 3))])


@pytest.mark.parametrize(("board", "extents", "former"), [("zmin", (6, 4, 4), (4.5, 3.5, 2.5)), ("zmax", (6, 4, 4), (4.5, 3.5, 2.5)), ("ymax", (6, 4, 4), (4.5, 3.5, 2.5))])
def test_the_cast_of_a_tray_is_its_cavity_with_the_board_side_down(tmp_path, board, extents, former):
    from helpers import write_mould

    from hydrotact.mesh import make_mould_cavity

    surface, transform = make_mould_cavity(write_mould(tmp_path / "tray.stl", **TRAY), units="mm", board=board)
    assert surface.is_watertight and surface.is_winding_consistent
    np.testing.assert_allclose(surface.volume, (6 * 4 * 4 - 1) * 1e-9, rtol=1e-9)  # the cavity less the former
    lo, hi = surface.bounds
    size = hi - lo
    np.testing.assert_allclose(sorted(size), sorted(np.array(extents) * 1e-3), atol=1e-12)
    np.testing.assert_allclose([lo[2], lo[0] + hi[0], lo[1] + hi[1]], 0.0, atol=1e-12)  # on z = 0, centred in x and y
    # The transform takes the mould's coordinates (mm) to the cast's (m): the board side
    # down; the former's centre (in the mould) lies within the cast's box.
    centre = transform @ np.array([*former, 1.0])
    down = np.zeros(3)
    down["xyz".index(board[0])] = 1.0 if board.endswith("max") else -1.0
    np.testing.assert_allclose(transform[:3, :3] @ down, [0.0, 0.0, -1e-3], atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(transform[:3, :3]), 1e-9, rtol=1e-12)
    assert np.all(centre[:3] > lo) and np.all(centre[:3] < hi)
    if board == "zmin":  # the floor, where the former stands, is the board side
        np.testing.assert_allclose(centre[2], 0.5e-3, atol=1e-12)


def test_a_closed_mould_of_two_parts_casts_its_enclosed_void(tmp_path):
    from helpers import write_mould

    from hydrotact.mesh import load_tet_mesh, make_mould_cavity

    cavity = ((2, 3, 2), (8, 7, 6))
    bottom = write_mould(tmp_path / "bottom.stl", ((0, 0, 0), (10, 10, 4)), [cavity])
    top = write_mould(tmp_path / "top.stl", ((0, 0, 4), (10, 10, 8)), [cavity])
    surface, _ = make_mould_cavity([bottom, top], units="mm", board="xmax")
    np.testing.assert_allclose(surface.volume, 96e-9, rtol=1e-9)
    np.testing.assert_allclose(surface.bounds, [[-2e-3, -2e-3, 0.0], [2e-3, 2e-3, 6e-3]], atol=1e-12)  # mould x (6 mm) stands up
    # Each part alone is an open tray whose cast is half the void.
    np.testing.assert_allclose(make_mould_cavity(bottom, units="mm")[0].volume, 48e-9, rtol=1e-9)
    # Meshed: the board side bonded (core), every other face free, the volume kept.
    mesh = load_tet_mesh([str(bottom), str(top)], units="mm", board="xmax", edge_length=1.0)
    np.testing.assert_allclose(float(np.sum(calc_signed_volumes(mesh.vertices, mesh.tets))), 96e-9, rtol=2e-3)
    tags = np.asarray(mesh.face_tags)
    core = np.asarray(mesh.vertices)[np.asarray(mesh.boundary_faces)[tags == CORE]]
    np.testing.assert_allclose(core[..., 2], 0.0, atol=1e-9)
    # The board face's area to TetWild's envelope (it may round a rim vertex off the face
    # by up to 1e-3 of the diagonal: CI's build of it gave 1.59983e-5 m², 1e-4 short).
    np.testing.assert_allclose(np.sum(0.5 * np.linalg.norm(np.cross(core[:, 1] - core[:, 0], core[:, 2] - core[:, 0]), axis=1)), 16e-6, rtol=2e-3)


@pytest.mark.parametrize(
    ("parts", "fragments"),
    [
        ([dict(outer=((0, 0, 0), (10, 8, 6)))], ["box.stl", "has no cavity"]),
        ([dict(outer=((0, 0, 0), (20, 8, 6)), hollows=[((2, 2, 2), (8, 6, 6.5)), ((12, 2, 2), (18, 6, 6.5))])], ["box.stl", "not one piece", "two largest hollows (96, 96 mm³)"]),
        ([dict(outer=((0, 0, 0), (20, 8, 6)), hollows=[((2, 2, 2), (8, 6, 4)), ((12, 2, 2), (18, 6, 4))])], ["box.stl", "not one piece", "2 enclosed cavities"]),
    ],
    ids=["convex", "two-open-cavities", "two-enclosed-cavities"],
)
def test_a_mould_without_one_cavity_is_refused(tmp_path, parts, fragments):
    from helpers import write_mould

    from hydrotact import HydrotactError
    from hydrotact.mesh import make_mould_cavity

    paths = [write_mould(tmp_path / "box.stl", **part) for part in parts]
    with pytest.raises(HydrotactError) as error:
        make_mould_cavity(paths, units="mm")
    for fragment in fragments:
        assert fragment in str(error.value), (fragment, str(error.value))
