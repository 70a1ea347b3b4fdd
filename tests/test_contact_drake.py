"""hydrotact's contact surfaces against Drake's, on identical meshes and fields.

Drake loads hydrotact's meshes (legacy VTK, compliant, so it uses the distance field
p = E d / max d, which hydrotact reproduces exactly) and rigid probes (OBJ), at the
same poses. Total area, force on the sensor and centroid must agree to 1e-9 (the issue asks 1e-6).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from drake_reference import OFF_AXIS_CASES, DrakeScene, drake_contact_surfaces, integrate_drake_surface, off_axis_case, pressing_plane_pose
from helpers import lowest_vertex

from hydrotact.contact import HalfSpace, compute_contact_surface, make_cylinder_probe, make_pose
from hydrotact.field import calc_distance_field, make_pressure_field
from hydrotact.mesh import make_ball, make_seed_mesh, read_mesh, write_mesh

pytest.importorskip("pydrake")
pytestmark = pytest.mark.drake

MODULUS = 2e5
RTOL = 1e-9  # the issue asks 1e-6; measured agreement is ~1e-15 (benchmarks/RESULTS.md)


def _sensor(tmp_path, mesh, name):
    path = write_mesh(mesh, tmp_path / f"{name}.vtk")
    mesh, _ = read_mesh(path)
    return path, mesh, make_pressure_field(mesh, calc_distance_field(mesh), MODULUS)


def _compare(ours, drake_surfaces):
    assert len(drake_surfaces) == 1
    surface, soft_is_M = drake_surfaces[0]
    area, force, centroid, _, _ = integrate_drake_surface(surface, soft_is_M)
    np.testing.assert_allclose(area, surface.total_area(), rtol=1e-12)
    np.testing.assert_allclose(centroid, surface.centroid(), rtol=1e-9, atol=1e-15)
    scale = np.linalg.norm(force)
    np.testing.assert_allclose(float(ours.total_area), area, rtol=RTOL)
    np.testing.assert_allclose(np.asarray(ours.calc_force()), force, rtol=RTOL, atol=RTOL * scale)
    np.testing.assert_allclose(np.asarray(ours.centroid_S), centroid, rtol=RTOL, atol=RTOL * np.linalg.norm(centroid))
    return area, force


@pytest.mark.parametrize(("name", "depth"), [("sphere8", 0.5e-3), ("sphere8", 1e-3), ("sphere8", 2e-3), ("ellipsoid8", 1e-3)])
def test_curved_sensor_against_a_half_space(tmp_path, name, depth):
    from pydrake.geometry import HalfSpace as DrakeHalfSpace

    path, mesh, field = _sensor(tmp_path, make_seed_mesh(name), name)
    top = float(np.asarray(mesh.vertices)[:, 2].max())
    ours, _ = compute_contact_surface(field, HalfSpace(), make_pose([0.0, 0.0, top - depth]))
    area, force = _compare(ours, drake_contact_surfaces(path, MODULUS, DrakeHalfSpace(), X_WO=pressing_plane_pose(top - depth)))
    assert force[2] < 0 and area > 0


@pytest.mark.parametrize(("label", "x", "y"), [("centre", 0.0, 0.0), ("next cell", 2.2e-3, 0.0), ("overhanging edge", 6.2e-3, 1.1e-3)])
def test_pad_against_the_2mm_cylinder(tmp_path, label, x, y):
    path, mesh, field = _sensor(tmp_path, make_seed_mesh("pad5x5"), "pad5x5")
    probe = make_cylinder_probe(2e-3, length=6e-3)
    probe_path = tmp_path / "probe.obj"
    probe.write_obj(probe_path)
    X_SR = np.eye(4)
    X_SR[:3, 3] = [x, y, 4e-3 - 0.4e-3]
    ours, _ = compute_contact_surface(field, probe, make_pose(X_SR[:3, 3]))
    area, force = _compare(ours, drake_contact_surfaces(path, MODULUS, str(probe_path), X_WO=X_SR))
    assert force[2] < 0


def test_two_soft_balls(tmp_path):
    ball = make_ball(5e-3, 4)
    path_a, mesh_a, field_a = _sensor(tmp_path, ball, "a")
    path_b, mesh_b, field_b = _sensor(tmp_path, ball, "b")
    X_SB = make_pose([1.0e-3, 0.5e-3, 9.2e-3], [0.3, -0.2, 0.1])
    ours, _ = compute_contact_surface(field_a, field_b, X_SB)
    area, force = _compare(ours, drake_contact_surfaces(path_a, MODULUS, str(path_b), X_WO=np.asarray(X_SB.as_matrix()), other_modulus=MODULUS))
    assert force[2] < 0 and int(ours.num_polygons) > 50


@pytest.mark.parametrize("label", list(OFF_AXIS_CASES))
def test_off_axis_tilted_and_past_the_mid_plane(tmp_path, label):
    field, probe, X_SR, drake = off_axis_case(label, tmp_path, MODULUS)
    ours, _ = compute_contact_surface(field, probe, X_SR)
    area, force = _compare(ours, drake)
    assert area > 0 and np.linalg.norm(force) > 0


# --- Ties walked in ulps and picometres, against Drake (issue 48) ---------------------

TIE_ULPS = (0, 1, -1, 2, -2, 16, -16, 1024, -1024)
TIE_METRES = (1e-13, -1e-13, 1e-12, -1e-12)
TIE_STEP = 1e-9  # Drake is compared exactly this far to either side


def _interior_face_below_the_top(mesh, depth=0.4e-3):
    """sphere8: the interior tet face (shared by two tets) nearest the axis about
    `depth` below the top, as (centroid, unit normal pointing down into the dome)."""
    vertices, tets = np.asarray(mesh.vertices), np.asarray(mesh.tets)
    faces = np.sort(np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]]), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    interior = unique[counts == 2]
    centroids = vertices[interior].mean(axis=1)
    normals = np.cross(vertices[interior[:, 1]] - vertices[interior[:, 0]], vertices[interior[:, 2]] - vertices[interior[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    top = vertices[:, 2].max()
    k = np.argmin(10 * np.abs(centroids[:, 2] - (top - depth)) + np.hypot(centroids[:, 0], centroids[:, 1]))
    return centroids[k], -normals[k] * np.sign(normals[k, 2])


def _tie_case(label, mesh):
    """(probe, translation, rotation vector, unit walk direction, capacity) of a probe
    exactly on a tie of the mesh; the capacities hold each walk (measured)."""
    from scipy.spatial.transform import Rotation

    from hydrotact.contact import Capacity, make_box_probe

    down = np.array([0.0, 0.0, -1.0])
    if label == "face on a horizontal layer":  # the cylinder's tip on the 3.5 mm vertex layer
        return make_cylinder_probe(2e-3, length=6e-3), np.array([0.0, 0.0, 3.5e-3]), np.zeros(3), down, Capacity(256, 256, 5632, 2816)
    if label == "faces on vertical vertex planes":  # the box's sides on x = -0.55, 1.65 mm and y = +-1.1 mm, walked along x
        box = make_box_probe((2.2e-3, 2.2e-3, 2e-3))
        return box, np.array([0.55e-3, 0.0, 4e-3 - 0.37e-3]), np.zeros(3), np.array([1.0, 0.0, 0.0]), Capacity(256, 24, 4096, 1024)
    if label == "vertex on a vertex":  # a box corner first, on the vertex (0.55, 0.55, 3.5) mm
        box = make_box_probe((4e-3, 4e-3, 2e-3))
        turn = Rotation.align_vectors([down], [np.array([2.0, 2.0, 1.0]) / 3.0])[0].as_rotvec()
        return box, np.array([0.55e-3, 0.55e-3, 3.5e-3]) - lowest_vertex(box, turn), turn, down, Capacity(640, 8, 4096, 256)
    if label == "edge along an edge":  # a box edge first, along the mesh edges y = 0, z = 3.5 mm
        box = make_box_probe((3e-3, 3e-3, 2e-3))
        turn = np.array([np.pi / 4, 0.0, 0.0])
        corner = lowest_vertex(box, turn)
        return box, np.array([0.0, -corner[1], 3.5e-3 - corner[2]]), turn, down, Capacity(288, 16, 4096, 1024)
    # "face in an interior tet face's plane" on sphere8: a box's bottom, the face 0.4 mm deep
    centroid, normal = _interior_face_below_the_top(mesh)
    turn = Rotation.align_vectors([normal], [down])[0].as_rotvec()
    return make_box_probe((2e-3, 2e-3, 2e-3)), centroid, turn, normal, Capacity(256, 24, 704, 1024)


@pytest.mark.parametrize(
    ("sensor", "label"),
    [
        ("pad5x5", "face on a horizontal layer"),
        ("pad5x5", "faces on vertical vertex planes"),
        ("pad5x5", "vertex on a vertex"),
        ("pad5x5", "edge along an edge"),
        ("sphere8", "face in an interior tet face's plane"),
    ],
)
def test_ties_walked_in_ulps_against_drake(tmp_path, sensor, label):
    """A probe exactly on a tie of the mesh, walked along the press (or across the tie
    plane) by 0, +-1, +-2, +-16, +-1024 ulps of the walked coordinate and +-1e-13,
    +-1e-12 m: the area and force stay on Drake's line through the poses +-1 nm off
    the tie (to 2e-8 of their size; measured: 5e-9 at most, sphere8's -1e-12 m, within
    the tie tolerance's band), and equal Drake's at +-1 nm (1e-9).

    Drake itself does not hold this line at the tie: it counts a face lying on a tet
    face layer in both tets (pad5x5 at 0: 8.203 mm^2 for 6.272), drops a little at -1
    ulp (6.266), counts part of a side face twice at +1e-13 m (8.171 for 8.096), and
    loses 0.1 % on sphere8 at 0 and +1 ulp (Drake 1.51): so the line is Drake's, not
    its value at each pose."""
    from hydrotact.contact import make_tet_clusters

    path, mesh, field = _sensor(tmp_path, make_seed_mesh(sensor), sensor)
    probe, translation, turn, walk, capacity = _tie_case(label, mesh)
    axis = int(np.argmax(np.abs(walk)))
    steps, offsets = [], []
    for ulps in TIE_ULPS:  # the walked coordinate moved by whole ulps, as a pose written in mm lands
        moved = translation.copy()
        moved[axis] += ulps * np.spacing(moved[axis]) * np.sign(walk[axis])
        steps.append(moved)
        offsets.append(ulps * np.spacing(translation[axis]) * abs(walk[axis]))  # along the walk
    for metres in (*TIE_METRES, TIE_STEP, -TIE_STEP):
        steps.append(translation + metres * walk)
        offsets.append(metres)
    steps, offsets = np.asarray(steps), np.asarray(offsets)
    poses = jax.vmap(make_pose)(jnp.asarray(steps), jnp.asarray(np.tile(turn, (len(steps), 1))))
    ours, _ = compute_contact_surface(field, probe, poses, capacity, make_tet_clusters(field.vertices, field.tets))
    area = np.asarray(ours.total_area)
    force = np.asarray(jax.vmap(lambda s: s.calc_force())(ours))

    probe_path = tmp_path / "probe.obj"
    probe.write_obj(probe_path)
    scene = DrakeScene(path, MODULUS, str(probe_path))
    drake_area, drake_force = [], []
    for k in (-2, -1):  # the sensor at X_SO^-1 with the probe at the world's origin: Drake's force in S is R_SO F_W
        X_SO = np.asarray(make_pose(steps[k], turn).as_matrix())
        ((surface, soft_is_M),) = scene.query(np.linalg.inv(X_SO))
        a, f, *_ = integrate_drake_surface(surface, soft_is_M)
        drake_area.append(a)
        drake_force.append(X_SO[:3, :3] @ f)
    drake_area, drake_force = np.asarray(drake_area), np.asarray(drake_force)
    np.testing.assert_allclose(area[-2:], drake_area, rtol=1e-9, err_msg=f"{label}: area 1 nm off")
    np.testing.assert_allclose(force[-2:], drake_force, rtol=1e-9, atol=1e-9 * np.abs(drake_force).max(), err_msg=f"{label}: force 1 nm off")
    # Drake's line through +-1 nm, at each walked offset
    fraction = (offsets[:-2] + TIE_STEP) / (2 * TIE_STEP)
    line_area = drake_area[1] + fraction * (drake_area[0] - drake_area[1])
    line_force = drake_force[1] + fraction[:, None] * (drake_force[0] - drake_force[1])
    np.testing.assert_allclose(area[:-2], line_area, rtol=2e-8, err_msg=f"{label}: area on the tie")
    np.testing.assert_allclose(force[:-2], line_force, rtol=0, atol=2e-8 * np.linalg.norm(drake_force, axis=1).max(), err_msg=f"{label}: force on the tie")
    assert np.all(area > 0) and np.all(np.linalg.norm(force, axis=1) > 0)
