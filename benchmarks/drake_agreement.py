"""Measure how closely hydrotact's contact surfaces agree with Drake's.

The cases of tests/test_contact_drake.py (which asserts 1e-9): the first ones, then
the tilted, edge-first, off-axis and past-the-mid-plane poses of
`drake_reference.OFF_AXIS_CASES`; printed as the relative differences in total area,
force vector and centroid.
Run: `.venv/bin/python benchmarks/drake_agreement.py`.
"""

import sys
import tempfile
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
from drake_reference import OFF_AXIS_CASES, drake_contact_surfaces, integrate_drake_surface, off_axis_case, pressing_plane_pose  # noqa: E402

from hydrotact.contact import HalfSpace, compute_contact_surface, make_cylinder_probe, make_pose  # noqa: E402
from hydrotact.field import calc_distance_field, make_pressure_field  # noqa: E402
from hydrotact.mesh import make_ball, make_seed_mesh, read_mesh, write_mesh  # noqa: E402

MODULUS = 2e5


def main():
    from pydrake.geometry import HalfSpace as DrakeHalfSpace

    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)

        def sensor(mesh, name):
            path = write_mesh(mesh, scratch / f"{name}.vtk")
            mesh, _ = read_mesh(path)
            return path, mesh, make_pressure_field(mesh, calc_distance_field(mesh), MODULUS)

        cases = []
        for name, depth in (("sphere8", 0.5e-3), ("sphere8", 1e-3), ("sphere8", 2e-3), ("ellipsoid8", 1e-3)):
            path, mesh, field = sensor(make_seed_mesh(name), name)
            top = float(np.asarray(mesh.vertices)[:, 2].max())
            cases.append((f"{name} vs half-space, {depth * 1e3:g} mm", field, HalfSpace(), make_pose([0, 0, top - depth]),
                          lambda path=path, top=top, depth=depth: drake_contact_surfaces(path, MODULUS, DrakeHalfSpace(), X_WO=pressing_plane_pose(top - depth))))
        path, mesh, field = sensor(make_seed_mesh("pad5x5"), "pad5x5")
        probe = make_cylinder_probe(2e-3, length=6e-3)
        probe.write_obj(scratch / "probe.obj")
        for label, x, y in (("centre", 0.0, 0.0), ("next cell", 2.2e-3, 0.0), ("overhanging edge", 6.2e-3, 1.1e-3)):
            X = np.eye(4)
            X[:3, 3] = [x, y, 3.6e-3]
            cases.append((f"pad5x5 vs 2 mm cylinder, {label}", field, probe, make_pose(X[:3, 3]),
                          lambda X=X, path=path: drake_contact_surfaces(path, MODULUS, str(scratch / "probe.obj"), X_WO=X)))
        path_a, _, field_a = sensor(make_ball(5e-3, 4), "a")
        path_b, _, field_b = sensor(make_ball(5e-3, 4), "b")
        X_SB = make_pose([1.0e-3, 0.5e-3, 9.2e-3], [0.3, -0.2, 0.1])
        cases.append(("two soft balls (soft-soft)", field_a, field_b, X_SB,
                      lambda: drake_contact_surfaces(path_a, MODULUS, str(path_b), X_WO=np.asarray(X_SB.as_matrix()), other_modulus=MODULUS)))
        for label in OFF_AXIS_CASES:
            field, other, X, drake_surfaces = off_axis_case(label, scratch, MODULUS)
            cases.append((label, field, other, X, lambda drake_surfaces=drake_surfaces: drake_surfaces))
        print("| case | polygons (ours / Drake) | area rel. diff | force rel. diff | centroid rel. diff |")
        print("|---|---:|---:|---:|---:|")
        for label, field, other, X, drake in cases:
            ours, _ = compute_contact_surface(field, other, X)
            (surface, soft_is_M), = drake()
            area, force, centroid, _, _ = integrate_drake_surface(surface, soft_is_M)
            d_area = abs(float(ours.total_area) - area) / area
            d_force = np.linalg.norm(np.asarray(ours.calc_force()) - force) / np.linalg.norm(force)
            d_centroid = np.linalg.norm(np.asarray(ours.centroid_S) - centroid) / np.linalg.norm(centroid)
            print(f"| {label} | {int(ours.num_polygons)} / {surface.poly_mesh_W().num_faces()} | {d_area:.1e} | {d_force:.1e} | {d_centroid:.1e} |")
            rows.append((label, d_area, d_force, d_centroid))


if __name__ == "__main__":
    main()
