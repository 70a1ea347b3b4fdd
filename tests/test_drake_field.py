"""Drake loads hydrotact's legacy VTK as a compliant mesh and, on it, uses exactly
hydrotact's distance field p = E d / max d."""

import jax.numpy as jnp
import numpy as np
import pytest
from drake_reference import drake_contact_surfaces, pressing_plane_pose
from helpers import locate

from hydrotact.field import calc_distance_field, make_pressure_field
from hydrotact.mesh import make_seed_mesh, read_mesh, write_mesh

pytest.importorskip("pydrake")
pytestmark = pytest.mark.drake

MODULUS = 2.5e5


@pytest.mark.parametrize(("name", "depth"), [("pad5x5", 0.4e-3), ("sphere8", 1e-3), ("ellipsoid8", 1e-3)])
def test_drake_pressures_equal_the_distance_field(tmp_path, name, depth):
    from pydrake.geometry import HalfSpace

    path = write_mesh(make_seed_mesh(name), tmp_path / f"{name}.vtk")
    mesh, _ = read_mesh(path)  # exactly what Drake reads
    top = float(np.asarray(mesh.vertices)[:, 2].max())
    surfaces = drake_contact_surfaces(path, MODULUS, HalfSpace(), X_WO=pressing_plane_pose(top - depth))
    assert len(surfaces) == 1
    surface, _ = surfaces[0]
    polygons = surface.poly_mesh_W()
    points = np.array([polygons.vertex(i) for i in range(polygons.num_vertices())])
    drake_pressure = np.array([surface.poly_e_MN().EvaluateAtVertex(i) for i in range(polygons.num_vertices())])
    assert len(points) > 20
    np.testing.assert_allclose(points[:, 2], top - depth, atol=1e-12)

    field = make_pressure_field(mesh, calc_distance_field(mesh), MODULUS)
    tets, _ = locate(np.asarray(mesh.vertices), np.asarray(mesh.tets), points)
    ours = np.asarray(field.calc_pressure(jnp.asarray(points), jnp.asarray(tets)))
    np.testing.assert_allclose(ours, drake_pressure, rtol=1e-9, atol=1e-9 * MODULUS)
    assert drake_pressure.max() > 0.05 * MODULUS
