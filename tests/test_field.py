"""The strain field: closed forms, convergence order, scikit-fem, gradients, jit/vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import central_difference

from hydrotact.field import (
    calc_distance_field,
    make_laplace_problem,
    make_pressure_field,
    solve_strain,
)
from hydrotact.mesh import CORE, make_box, make_seed_mesh, make_spherical_shell


def test_slab_field_is_linear_to_1e_10():
    """Core at z = 0, free at z = h, insulated sides: e = 1 - z / h exactly."""
    height = 3e-3
    mesh = make_box((5e-3, 4e-3, height), 0.5e-3, sides="insulated")
    problem = make_laplace_problem(mesh)
    solution = solve_strain(problem, rtol=1e-14)
    z = np.asarray(mesh.vertices)[:, 2]
    np.testing.assert_allclose(np.asarray(solution.strain), 1.0 - z / height, rtol=0, atol=1e-10)
    assert float(solution.relative_residual) < 1e-12


def test_general_linear_dirichlet_data_is_reproduced_exactly():
    """Any linear function is harmonic and lies in the P1 space: it is reproduced."""
    mesh = make_seed_mesh("ellipsoid8")
    problem = make_laplace_problem(mesh)
    vertices = np.asarray(mesh.vertices)
    exact = 0.3 + vertices @ np.array([40.0, -25.0, 60.0])
    solution = solve_strain(problem, dirichlet_values=exact, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(solution.strain), exact, rtol=0, atol=1e-10)


def _shell_l2_error(num_layers, r0=0.5, r1=1.0):
    mesh = make_spherical_shell(r0, r1, num_layers)
    strain = np.asarray(solve_strain(make_laplace_problem(mesh), rtol=1e-13).strain)
    vertices, tets = np.asarray(mesh.vertices), np.asarray(mesh.tets)

    def exact(points):
        r = np.linalg.norm(points, axis=-1)
        return (1 / r - 1 / r1) / (1 / r0 - 1 / r1)

    # Degree-3 quadrature on each tet (Keast): centroid weight -4/5, four points 9/20.
    rule = [(np.full(4, 0.25), -0.8)] + [
        (np.where(np.arange(4) == k, 0.5, 1 / 6), 0.45) for k in range(4)
    ]
    p = vertices[tets]
    volume = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6
    error_squared = 0.0
    for bary, weight in rule:
        points = np.einsum("k,tkd->td", bary, p)
        approx = strain[tets] @ bary
        error_squared += weight * np.sum(volume * (approx - exact(points)) ** 2)
    h = 1.0 / num_layers
    return h, np.sqrt(error_squared), mesh


def test_spherical_shell_converges_at_second_order():
    results = [_shell_l2_error(n) for n in (2, 3, 4, 6)]
    h = np.array([r[0] for r in results])
    error = np.array([r[1] for r in results])
    assert np.all(np.diff(error) < 0), error
    slope = np.polyfit(np.log(h), np.log(error), 1)[0]
    assert slope >= 1.8, (slope, error)
    # The core (inner sphere) carries e = 1, the skin e = 0.
    mesh = results[-1][2]
    strain = np.asarray(solve_strain(make_laplace_problem(mesh)).strain)
    np.testing.assert_array_equal(strain[mesh.vertices_tagged(CORE)], 1.0)


def test_agrees_with_scikit_fem_on_the_same_mesh():
    skfem = pytest.importorskip("skfem")
    from skfem.helpers import dot, grad

    mesh = make_seed_mesh("sphere8")
    problem = make_laplace_problem(mesh)
    ours = np.asarray(solve_strain(problem, rtol=1e-14).strain)

    reference_mesh = skfem.MeshTet(np.asarray(mesh.vertices).T.copy(), np.asarray(mesh.tets).T.copy())
    basis = skfem.Basis(reference_mesh, skfem.ElementTetP1())

    @skfem.BilinearForm
    def laplace(u, v, _):
        return dot(grad(u), grad(v))

    stiffness = laplace.assemble(basis)
    fixed_values = np.where(np.asarray(problem.is_core_vertex), 1.0, 0.0)
    fixed = np.flatnonzero(np.asarray(problem.is_core_vertex) | np.asarray(problem.is_free_vertex))
    theirs = skfem.solve(*skfem.condense(stiffness, x=fixed_values, D=fixed))
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-8)


def _region_mean(problem, mesh):
    """Mean strain over the vertices inside a ball below the pad's centre."""
    vertices = np.asarray(mesh.vertices)
    region = jnp.asarray(np.linalg.norm(vertices - np.array([0.3e-3, -0.2e-3, 1.2e-3]), axis=1) < 1.5e-3)

    def mean_strain(V, core_value=1.0, free_value=0.0):
        strain = solve_strain(problem, vertices=V, core_value=core_value, free_value=free_value, rtol=1e-13).strain
        return jnp.sum(jnp.where(region, strain, 0.0)) / jnp.sum(region)

    return mean_strain


def test_gradient_wrt_vertex_positions_matches_finite_differences(rng):
    mesh = make_box((4e-3, 4e-3, 2.5e-3), 0.5e-3, center_xy=(0.0, 0.0))
    problem = make_laplace_problem(mesh)
    mean_strain = _region_mean(problem, mesh)
    V = jnp.asarray(problem.vertices)
    gradient = jax.grad(mean_strain)(V)
    for _ in range(3):
        direction = jnp.asarray(rng.normal(size=V.shape)) * 1e-4  # moves every vertex, boundary too
        fd = central_difference(mean_strain, V, direction, 1e-3)
        np.testing.assert_allclose(float(jnp.sum(gradient * direction)), fd, rtol=1e-6, atol=1e-12)


def test_gradient_wrt_boundary_values_and_modulus_matches_finite_differences():
    mesh = make_box((4e-3, 4e-3, 2.5e-3), 0.5e-3)
    problem = make_laplace_problem(mesh)
    mean_strain = _region_mean(problem, mesh)
    V = jnp.asarray(problem.vertices)
    d_core, d_free = jax.grad(lambda c, f: mean_strain(V, c, f), argnums=(0, 1))(1.0, 0.2)
    fd_core = central_difference(lambda c: mean_strain(V, c, 0.2), 1.0, 1.0, 1e-3)
    fd_free = central_difference(lambda f: mean_strain(V, 1.0, f), 0.2, 1.0, 1e-3)
    np.testing.assert_allclose(float(d_core), fd_core, rtol=1e-8)
    np.testing.assert_allclose(float(d_free), fd_free, rtol=1e-8)
    # Linear in the boundary values: the two sensitivities add up to one.
    np.testing.assert_allclose(float(d_core + d_free), 1.0, rtol=1e-9)

    strain = solve_strain(problem).strain
    region_points = jnp.asarray(np.asarray(mesh.vertices)[:40:3])

    def mean_pressure(modulus):
        field = make_pressure_field(mesh, strain, modulus)
        tets = jnp.zeros(region_points.shape[0], dtype=jnp.int32) + 7
        return jnp.mean(field.calc_pressure(region_points, tets) ** 2)

    d_modulus = jax.grad(mean_pressure)(2e5)
    np.testing.assert_allclose(float(d_modulus), central_difference(mean_pressure, 2e5, 1.0, 10.0), rtol=1e-7)


def test_pressure_field_interpolates_and_has_constant_gradient_on_the_slab():
    mesh = make_box((3e-3, 3e-3, 2e-3), 0.5e-3, sides="insulated")
    strain = solve_strain(make_laplace_problem(mesh), rtol=1e-14).strain
    field = make_pressure_field(mesh, strain, 1e5)
    np.testing.assert_allclose(np.asarray(field.calc_tet_pressure_gradients()), np.tile([0.0, 0.0, -1e5 / 2e-3], (mesh.num_tets, 1)), atol=1e-3)
    tets = np.asarray(mesh.tets)[:5]
    centroids = np.asarray(mesh.vertices)[tets].mean(axis=1)
    pressures = field.calc_pressure(jnp.asarray(centroids), jnp.arange(5))
    np.testing.assert_allclose(np.asarray(pressures), 1e5 * (1 - centroids[:, 2] / 2e-3), rtol=1e-9)


def test_jit_and_vmap_without_recompilation():
    mesh = make_box((4e-3, 4e-3, 2e-3), 0.5e-3)
    problem = make_laplace_problem(mesh)
    traces = []

    @jax.jit
    def peak_pressure(V, modulus, core_value):
        traces.append(1)
        field = make_pressure_field(mesh, solve_strain(problem, vertices=V, core_value=core_value).strain, modulus)
        return jnp.max(field.vertex_pressures)

    V = jnp.asarray(problem.vertices)
    first = peak_pressure(V, 1e5, 1.0)
    second = peak_pressure(V * 1.01, 2e5, 0.5)
    assert len(traces) == 1
    np.testing.assert_allclose([float(first), float(second)], [1e5, 1e5], rtol=1e-12)

    moduli = jnp.array([1e5, 2e5, 3e5])
    core_values = jnp.array([1.0, 0.5, 2.0])
    batched = jax.vmap(peak_pressure, in_axes=(None, 0, 0))(V, moduli, core_values)
    np.testing.assert_allclose(np.asarray(batched), np.asarray(moduli * core_values), rtol=1e-12)
    strains = jax.vmap(lambda c: solve_strain(problem, core_value=c).strain)(core_values)
    np.testing.assert_allclose(np.asarray(strains[1]), 0.5 * np.asarray(strains[0]), rtol=1e-8, atol=1e-12)


def test_float32_solve_meets_its_tolerance():
    mesh = make_seed_mesh("pad5x5", 1e-3)
    problem = make_laplace_problem(mesh)
    reference = np.asarray(solve_strain(problem).strain)
    single = solve_strain(problem, vertices=jnp.asarray(problem.vertices, jnp.float32))
    assert single.strain.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(single.strain), reference, atol=1e-4)


def test_distance_field_on_a_box_is_the_distance_to_the_nearest_face():
    size = np.array([4e-3, 3e-3, 2e-3])
    mesh = make_box(tuple(size), 0.5e-3, center_xy=(2e-3, 1.5e-3))
    vertices = np.asarray(mesh.vertices)
    distance = np.min(np.concatenate([vertices, size - vertices], axis=1), axis=1)
    e = np.asarray(calc_distance_field(mesh))
    np.testing.assert_allclose(e, distance / distance.max(), rtol=0, atol=1e-12)


def test_distance_field_on_a_shell_against_the_radius():
    errors = []
    for num_layers in (2, 4):
        mesh = make_spherical_shell(0.5, 1.0, num_layers)
        r = np.linalg.norm(np.asarray(mesh.vertices), axis=1)
        e = np.asarray(calc_distance_field(mesh))
        np.testing.assert_array_equal(e[mesh.vertices_tagged(CORE)], 0.0)
        distance = np.minimum(1.0 - r, r - 0.5)
        errors.append(np.max(np.abs(e - distance / distance.max())))
    # The faceted spheres lie up to a chord's sag inside the true ones; refining
    # shrinks the sag, and with it the difference.
    assert errors[1] < 0.6 * errors[0] and errors[1] < 0.02, errors


def test_core_depth_option_for_a_shape_without_core():
    from helpers import icosphere

    from hydrotact.mesh import tetrahedralize

    mesh = tetrahedralize(icosphere(radius=5e-3), 1e-3)
    problem = make_laplace_problem(mesh, core_depth=2e-3)
    vertices = np.asarray(mesh.vertices)
    deep = np.asarray(problem.is_core_vertex)
    assert deep.any() and np.all(np.linalg.norm(vertices[deep], axis=1) < 3.05e-3)
    strain = np.asarray(solve_strain(problem).strain)
    assert strain.min() == 0.0 and strain.max() == 1.0
    # By the maximum principle the field lies between the shell solutions whose core
    # spheres are inside and outside the (jagged) set of fixed vertices.
    r = np.maximum(np.linalg.norm(vertices, axis=1), 1e-6)

    def shell(r0):
        return np.clip((1 / r - 1 / 5e-3) / (1 / r0 - 1 / 5e-3), 0, 1)

    assert np.all(strain >= shell(2e-3) - 0.02) and np.all(strain <= shell(3.05e-3) + 0.02)
    assert np.mean(np.abs(strain - shell(2.6e-3))) < 0.05
