"""hydrotact's contact surfaces against Drake's, on identical meshes and fields.

Drake loads hydrotact's meshes (legacy VTK, compliant, so it uses the distance field
p = E d / max d, which hydrotact reproduces exactly) and rigid probes (OBJ), at the
same poses. Total area, force on the sensor and centroid must agree to 1e-9 (the issue asks 1e-6).
"""

import numpy as np
import pytest
from drake_reference import OFF_AXIS_CASES, drake_contact_surfaces, integrate_drake_surface, off_axis_case, pressing_plane_pose

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
