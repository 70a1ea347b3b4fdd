"""The elastic stage: linear elasticity on P2 tets (mixed P2-P0) and barometers'
receptive fields by reciprocity, checked against closed forms (Boussinesq, Cerruti,
Hertz), scikit-fem's mixed assembly on the same mesh, and central differences."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hydrotact import elastic
from hydrotact.field import calc_tet_gradients
from hydrotact.mesh import CORE, FREE, TetMesh, make_box, make_spherical_shell

# ---------------------------------------------------------------- closed forms
# Half-space z < 0, surface z = 0, a point force at the origin; depth zeta = -z.


def boussinesq_u(x, nu, shear, force=1.0):
    """Boussinesq: a normal force `force` pushing into the half-space (along -z)."""
    zeta = -x[2]
    radius = jnp.sqrt(x[0] ** 2 + x[1] ** 2 + zeta**2)
    c = force / (4.0 * jnp.pi * shear)
    radial = c * (zeta / radius**3 - (1.0 - 2.0 * nu) / (radius * (radius + zeta)))
    return jnp.stack([radial * x[0], radial * x[1], -c * (zeta**2 / radius**3 + 2.0 * (1.0 - nu) / radius)])


def cerruti_u(x, nu, shear, force=1.0):
    """Cerruti: a tangential force `force` along +x on the surface (Johnson, eq. 2.19)."""
    X, Y, zeta = x[0], x[1], -x[2]
    r = jnp.sqrt(X**2 + Y**2 + zeta**2)
    c, k = force / (4.0 * jnp.pi * shear), 1.0 - 2.0 * nu
    ux = c * (1 / r + X**2 / r**3 + k * (1 / (r + zeta) - X**2 / (r * (r + zeta) ** 2)))
    uy = c * (X * Y / r**3 - k * X * Y / (r * (r + zeta) ** 2))
    uz = c * (X * zeta / r**3 + k * X / (r * (r + zeta)))
    return jnp.stack([ux, uy, -uz])


def exact_stress(displacement, x, nu, shear):
    gradient = jax.jacfwd(displacement)(x, nu, shear)
    strain = 0.5 * (gradient + gradient.T)
    lam = 2.0 * shear * nu / (1.0 - 2.0 * nu)
    return lam * jnp.trace(strain) * jnp.eye(3) + 2.0 * shear * strain


def exact_pressure(displacement, points, nu):
    shear = 1.0 / (2.0 * (1.0 + nu))
    return np.asarray(jax.vmap(lambda x: -jnp.trace(exact_stress(displacement, x, nu, shear)) / 3.0)(jnp.asarray(points)))


@pytest.mark.parametrize("displacement", [boussinesq_u, cerruti_u])
def test_closed_forms_are_elastic_equilibria_with_a_free_surface(displacement):
    """The closed forms themselves (as written here): div sigma = 0 inside, no traction
    on the surface off the load, a unit resultant, and the hydrostatic pressure
    (1 + nu) P zeta / (3 pi rho^3) (Boussinesq) or (1 + nu) Q x / (3 pi rho^3) (Cerruti)."""
    nu = 0.3
    shear = 1.0 / (2.0 * (1.0 + nu))
    rng = np.random.default_rng(4)
    inside = rng.normal(size=(6, 3))
    inside[:, 2] = -np.abs(inside[:, 2]) - 0.1
    divergence = jax.vmap(lambda x: jnp.einsum("ijj->i", jax.jacfwd(lambda y: exact_stress(displacement, y, nu, shear))(x)))(jnp.asarray(inside))
    assert np.abs(divergence).max() < 1e-12
    surface = inside.copy()
    surface[:, 2] = 0.0
    traction = jax.vmap(lambda x: exact_stress(displacement, x, nu, shear)[:, 2])(jnp.asarray(surface))
    assert np.abs(traction).max() < 1e-12
    theta, phi = np.meshgrid((np.arange(240) + 0.5) * (np.pi / 2 / 240), np.arange(480) * (2 * np.pi / 480), indexing="ij")
    normals = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], -1).reshape(-1, 3)
    areas = (np.sin(theta) * (np.pi / 2 / 240) * (2 * np.pi / 480)).reshape(-1)
    stresses = jax.vmap(lambda x: exact_stress(displacement, x, nu, shear))(jnp.asarray(normals))
    resultant = np.einsum("qij,qj,q->i", stresses, normals, areas)  # what holds the hemisphere against the load
    expected = [0.0, 0.0, 1.0] if displacement is boussinesq_u else [-1.0, 0.0, 0.0]
    np.testing.assert_allclose(resultant, expected, atol=1e-4)
    radius = np.linalg.norm(inside, axis=1)
    along = -inside[:, 2] if displacement is boussinesq_u else inside[:, 0]
    np.testing.assert_allclose(exact_pressure(displacement, inside, nu), (1 + nu) * along / (3 * np.pi * radius**3), rtol=1e-12)


def _sub_block(edge, nu, displacement, size=4e-3, height=2e-3, gap=1.5e-3, ports=None):
    """Solve on a block of the half-space below the load (z in [-gap - height, -gap]),
    with the closed form's displacement on its sides and bottom and its traction on
    the top: the FE solution converges to the closed form, singularity excluded.

    **Returns:** (relative max displacement error at the nodes, relative errors of the
    port readings against the same port functional of the exact tet-mean pressures,
    relative L2 error of the tets' pressures, CG steps)."""
    box = make_box((size, size, height), edge, sides="core")
    vertices = np.asarray(box.vertices).copy()
    vertices[:, 2] -= height + gap
    mesh = TetMesh(vertices, box.tets, box.boundary_faces, box.face_tags)
    problem = elastic.make_elastic_problem(mesh, nu)
    shear = 1.0 / (2.0 * (1.0 + nu))
    nodes = problem.calc_node_positions()
    exact = np.asarray(jax.vmap(displacement, in_axes=(0, None, None))(nodes, nu, shear))
    quadrature = elastic.make_face_quadrature(problem, mesh.faces_tagged(FREE))
    stresses = jax.vmap(lambda x: exact_stress(displacement, x, nu, shear))(quadrature.points_S)
    loads = elastic.calc_face_loads(problem, quadrature, jnp.einsum("qij,qj->qi", stresses, quadrature.normals_S))
    multigrid = elastic.make_multigrid_preconditioner(problem) if problem.num_nodes > 10_000 else None
    solution = elastic.solve_elasticity(problem, loads, dirichlet_values=exact, multigrid=multigrid)
    u_error = np.abs(np.asarray(solution.displacements) - exact).max() / np.abs(exact).max()
    tets = np.asarray(mesh.tets)
    points = np.einsum("qi,tid->tqd", elastic._problem.TET_QUADRATURE, vertices[tets])
    tet_means = exact_pressure(displacement, points.reshape(-1, 3), nu).reshape(-1, 4).mean(axis=1)
    _, volumes = calc_tet_gradients(jnp.asarray(vertices), jnp.asarray(tets))
    volumes = np.asarray(volumes)
    p_error = np.sqrt(np.sum(volumes * (np.asarray(solution.pressures) - tet_means) ** 2) / np.sum(volumes * tet_means**2))
    read_error = None
    if ports is not None:
        readings = np.asarray(elastic.calc_port_readings(problem, solution.displacements, ports))
        weights = np.asarray(elastic.calc_port_weights(jnp.asarray(vertices), jnp.asarray(tets), ports))
        expected = weights @ tet_means
        read_error = np.abs(readings - expected).max() / np.abs(expected).max()
    return u_error, read_error, p_error, int(solution.num_steps)


_PORTS = elastic.make_barometer_ports(
    [[0.0, 0.0, -2.3e-3], [0.7e-3, 0.3e-3, -2.5e-3], [-0.9e-3, 0.5e-3, -2.8e-3], [0.2e-3, -0.8e-3, -3.0e-3]],
    np.tile([0.0, 0.0, 1.0], (4, 1)),
    np.full(4, 0.5e-3),
)


@pytest.mark.parametrize(
    ("displacement", "edges", "orders"),
    [
        # Boussinesq between 0.5 and 0.25 mm, in the asymptotic range: measured orders
        # 2.2 (u), 1.9 (ports), 1.7 (tet pressures)
        (boussinesq_u, (0.5e-3, 0.25e-3), (1.9, 1.7, 1.5)),
        # Cerruti between 1 and 0.5 mm (two and four tets through the block), still
        # pre-asymptotic: 1.75, 1.33, 1.41 (2.2, 1.8, 1.7 between 0.5 and 0.25 mm)
        (cerruti_u, (1e-3, 0.5e-3), (1.6, 1.2, 1.3)),
    ],
)
def test_converges_to_the_closed_form_at_the_element_order_without_locking(displacement, edges, orders):
    """Boussinesq and Cerruti: displacements and port readings converge at second
    order in h (P2 displacements, P0 pressure), the tets' pressures (against the
    exact tet means) at about 1.7; at nu = 0.49 and 0.499 the displacement and port
    errors stay within 2x of those at nu = 0.3 (no locking). The tets' own pressures
    are not held to that: at nu -> 0.5 they carry a mesh-scale oscillation (P2-P0 is
    not uniformly inf-sup stable in 3-D), which the port's average removes."""
    coarse = _sub_block(edges[0], 0.3, displacement, ports=_PORTS)
    fine = _sub_block(edges[1], 0.3, displacement, ports=_PORTS)
    measured = [np.log2(coarse[k] / fine[k]) for k in range(3)]
    for value, expected in zip(measured, orders, strict=True):
        assert value > expected, (measured, coarse, fine)
    assert fine[1] < 0.03
    for nu in (0.49, 0.499):
        nearly = _sub_block(0.5e-3, nu, displacement, ports=_PORTS)
        reference = {edges[0]: coarse, edges[1]: fine}[0.5e-3]
        assert nearly[0] < 2.0 * reference[0], (nu, nearly, reference)
        assert nearly[1] < 2.0 * reference[1], (nu, nearly, reference)


def hertz_axis_pressure(depth, a, p0, nu):
    """Hertz: the hydrostatic pressure -(sigma_z + 2 sigma_r) / 3 on the axis under the
    pressure p0 sqrt(1 - r^2 / a^2) (Johnson, eq. 3.45)."""
    s = depth / a
    sigma_z = -1.0 / (1.0 + s**2)
    sigma_r = -(1.0 + nu) * (1.0 - s * np.arctan(1.0 / s)) + 0.5 / (1.0 + s**2)
    return -(sigma_z + 2.0 * sigma_r) / 3.0 * p0


def _hertz_half_space_u(points, a, p0, nu):
    """The half-space's displacement under the Hertz pressure, Boussinesq integrated
    over the disk (r = a sin t, Gauss-Legendre in t: the integrand is smooth), at
    points away from it; and the load's total (2/3 pi a^2 p0)."""
    shear = 1.0 / (2.0 * (1.0 + nu))
    nodes, weights = np.polynomial.legendre.leggauss(24)
    t, w = (nodes + 1) * np.pi / 4, weights * np.pi / 4
    phi = (np.arange(48) + 0.5) * 2 * np.pi / 48
    T, P = np.meshgrid(t, phi, indexing="ij")
    rho = a * np.sin(T)
    area_weights = (p0 * np.cos(T) * a * np.sin(T) * a * np.cos(T) * w[:, None] * (2 * np.pi / 48)).reshape(-1)
    sources = np.stack([rho * np.cos(P), rho * np.sin(P), 0 * rho], -1).reshape(-1, 3)
    field = jax.vmap(lambda x: jnp.sum(area_weights[:, None] * jax.vmap(lambda y: boussinesq_u(x - y, nu, shear))(jnp.asarray(sources)), axis=0))
    return np.asarray(field(jnp.asarray(points))), float(area_weights.sum())


def _hertz_block(edge, nu, a=1.5e-3, size=6e-3, height=3e-3):
    """The Hertz pressure on the top of a 6 x 6 x 3 mm block of the half-space, the
    half-space's displacement on its sides and bottom: the relative error of three
    small ports on the axis (0.5, 1 and 1.5 a deep) against Hertz's closed form."""
    box = make_box((size, size, height), edge, sides="core")
    vertices = np.asarray(box.vertices).copy()
    vertices[:, 2] -= height
    mesh = TetMesh(vertices, box.tets, box.boundary_faces, box.face_tags)
    problem = elastic.make_elastic_problem(mesh, nu)
    nodes, fixed = np.asarray(problem.calc_node_positions()), np.asarray(problem.is_fixed)
    dirichlet = np.zeros_like(nodes)
    dirichlet[fixed], total = _hertz_half_space_u(nodes[fixed], a, 1.0, nu)
    np.testing.assert_allclose(total, 2.0 / 3.0 * np.pi * a**2, rtol=1e-12)
    quadrature = elastic.make_face_quadrature(problem, mesh.faces_tagged(FREE))
    radius = np.linalg.norm(np.asarray(quadrature.points_S)[:, :2], axis=1)
    tractions = np.zeros((len(radius), 3))
    tractions[:, 2] = -np.sqrt(np.clip(1.0 - (radius / a) ** 2, 0.0, None))
    loads = elastic.calc_face_loads(problem, quadrature, tractions)
    multigrid = elastic.make_multigrid_preconditioner(problem) if problem.num_nodes > 10_000 else None
    solution = elastic.solve_elasticity(problem, loads, dirichlet_values=dirichlet, multigrid=multigrid)
    depths = np.array([0.5, 1.0, 1.5]) * a
    ports = elastic.make_barometer_ports(np.stack([0 * depths, 0 * depths, -depths], 1), np.tile([0.0, 0.0, 1.0], (3, 1)), np.full(3, 0.1e-3))
    readings = np.asarray(elastic.calc_port_readings(problem, solution.displacements, ports))
    exact = hertz_axis_pressure(depths, a, 1.0, nu)
    return np.abs(readings - exact).max() / np.abs(exact).max()


def test_hertz_pressure_along_the_axis():
    """Under a Hertz pressure distribution (a sphere's contact), the pressure along the
    axis converges to Hertz's closed form: 3.4 % at 0.75 mm tets, 0.93 % at 0.375 mm
    (order 1.9, measured); at nu = 0.49 within 2x of nu = 0.3 (1.04 % at 0.375 mm)."""
    coarse, fine = _hertz_block(0.75e-3, 0.3), _hertz_block(0.375e-3, 0.3)
    assert fine < 0.015 and np.log2(coarse / fine) > 1.5, (coarse, fine)
    assert _hertz_block(0.75e-3, 0.49) < 2.0 * coarse


def _skfem_mixed(mesh, nu, modulus, traction, body):
    """scikit-fem's mixed P2-P0 assembly (quadratic vector displacements, one
    pressure per tet), the block saddle-point system solved directly."""
    import scipy.sparse as sp
    import skfem
    from skfem.helpers import ddot, div, sym_grad, trace

    m = skfem.MeshTet(np.asarray(mesh.vertices).T.copy(), np.asarray(mesh.tets).T.copy())
    basis_u = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP2()), intorder=4)
    basis_p = skfem.Basis(m, skfem.ElementTetP0(), intorder=4)
    mu, kappa = modulus / (2 * (1 + nu)), modulus / (3 * (1 - 2 * nu))

    @skfem.BilinearForm
    def deviatoric(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return 2 * mu * (ddot(eu, ev) - trace(eu) * trace(ev) / 3)

    @skfem.BilinearForm
    def divergence(u, q, w):
        return div(u) * q

    @skfem.BilinearForm
    def compliance(p, q, w):
        return p * q / kappa

    @skfem.LinearForm
    def surface(v, w):
        t = traction(w.x)
        return t[0] * v[0] + t[1] * v[1] + t[2] * v[2]

    @skfem.LinearForm
    def gravity(v, w):
        return body[0] * v[0] + body[1] * v[1] + body[2] * v[2]

    loaded = np.intersect1d(m.facets_satisfying(lambda x: np.abs(x[2]) > 1e-9), m.boundary_facets())
    f = surface.assemble(skfem.FacetBasis(m, basis_u.elem, facets=loaded, intorder=6)) + gravity.assemble(basis_u)
    B = divergence.assemble(basis_u, basis_p)
    system = sp.bmat([[deviatoric.assemble(basis_u), -B.T], [-B, -compliance.assemble(basis_p)]], format="csc")
    fixed = basis_u.get_dofs(m.facets_satisfying(lambda x: np.abs(x[2]) < 1e-9)).all()
    x = skfem.solve(*skfem.condense(system, np.concatenate([f, np.zeros(basis_p.N)]), D=fixed))
    return basis_u, x[: basis_u.N], x[basis_u.N :]


@pytest.mark.parametrize("nu", [0.3, 0.499])
def test_agrees_with_scikit_fem_on_the_same_mesh(nu):
    """Displacements at every P2 node and the tets' pressures agree with scikit-fem's
    mixed P2-P0 solve to 1e-8 relative (linear tractions on the skin, gravity; to 1e-7
    and 1e-6 at nu = 0.499, where the near-incompressible solve magnifies round-off)."""
    from scipy.spatial import cKDTree

    mesh = make_box((4e-3, 3e-3, 2e-3), 1e-3)
    modulus, body = 1e5, (0.0, 50.0, -200.0)

    def traction(x):
        return [0.3 + 0 * x[0], 0.1 * x[1] / 1e-3, -(1.0 + x[0] / 4e-3)]

    problem = elastic.make_elastic_problem(mesh, nu)
    quadrature = elastic.make_face_quadrature(problem, mesh.faces_tagged(FREE))
    tractions = np.stack(traction(np.asarray(quadrature.points_S).T), axis=-1)
    loads = elastic.calc_face_loads(problem, quadrature, tractions) + elastic.calc_body_loads(problem, body)
    solution = elastic.solve_elasticity(problem, loads, modulus=modulus, rtol=1e-12)
    basis, u_ref, p_ref = _skfem_mixed(mesh, nu, modulus, traction, body)
    distance, node = cKDTree(np.asarray(problem.calc_node_positions())).query(basis.doflocs.T)
    assert distance.max() == 0.0
    ours = np.zeros(basis.N)
    for k, indices in enumerate(basis.split_indices()):
        ours[indices] = np.asarray(solution.displacements)[node[indices], k]
    # at nu = 0.499 (kappa / mu = 750) the solver's round-off floor (CG stalls at a
    # relative residual of 1e-12) is magnified in u (1.4e-8 measured on an AMD EPYC,
    # under 1e-8 on the Intel Xeon) and more in p = -kappa div u (1.2e-7 on the AMD,
    # 6.5e-8 on the Intel)
    tolerance = 1e-8 if nu < 0.49 else 1e-7
    assert np.abs(ours - u_ref).max() <= tolerance * np.abs(u_ref).max()
    assert np.abs(np.asarray(solution.pressures) - p_ref).max() <= (tolerance if nu < 0.49 else 1e-6) * np.abs(p_ref).max()
    # stress recovered at the centroids is the mixed form's: tr(sigma) / 3 = -p
    stress = elastic.calc_stress(problem, solution, modulus=modulus)
    np.testing.assert_allclose(-np.trace(np.asarray(stress), axis1=1, axis2=2) / 3, np.asarray(solution.pressures), rtol=1e-12, atol=1e-12 * np.abs(p_ref).max())


# ------------------------------------------------------- reciprocity and gradients


@pytest.fixture(scope="module")
def pad():
    """A coarse pad (the pad5x5 block at 2 mm cells), a sphere pressed off-axis into
    it, and four ports (pressure and normal stress) under the board's skin."""
    from hydrotact.contact import make_pose, make_sphere_probe
    from hydrotact.field import make_laplace_problem, make_pressure_field, solve_strain
    from hydrotact.mesh import make_seed_mesh

    mesh = make_seed_mesh("pad5x5", 2.2e-3)
    field = make_pressure_field(mesh, solve_strain(make_laplace_problem(mesh)).strain, 1e5)
    probe = make_sphere_probe(3e-3, subdivisions=2)
    ports = elastic.make_barometer_ports(
        [[0.3e-3, -0.2e-3, 0.0], [2.2e-3, 0.0, 0.0], [-2.2e-3, 2.2e-3, 0.4e-3], [0.0, -4.4e-3, 0.0]],
        [[0.0, 0.0, 1.0], [0.2, 0.0, 1.0], [0.0, -0.3, 1.0], [0.0, 0.0, 1.0]],
        [0.5e-3, 0.7e-3, 0.5e-3, 0.6e-3],
        ["pressure", "normal_stress", "pressure", "normal_stress"],
    )
    X_SR = make_pose([0.37e-3, -0.21e-3, 4e-3 - 0.61e-3])
    return mesh, field, probe, ports, X_SR


# The press needs 54 tets, 52 probe triangles, 558 pairs and 138 polygons: buffers
# about twice that (compiling the contact kernel for 4096-slot buffers cost ~15 s).


def _capacity():
    from hydrotact.contact import Capacity

    return Capacity(128, 128, 1024, 256)


def _readings(mesh, field, probe, ports, X_SR, nu=0.49):
    from hydrotact.contact import calc_contact_surface

    problem = elastic.make_elastic_problem(mesh, nu)
    fields = elastic.calc_receptive_fields(problem, ports, rtol=1e-12)
    surface = calc_contact_surface(field, probe, X_SR, _capacity())
    return problem, fields, surface, elastic.calc_elastic_readings(fields, surface)


def test_reading_by_reciprocity_equals_the_direct_solve(pad):
    """A contact surface's readings from the receptive fields equal those of the
    direct solve with its tractions as loads (Maxwell-Betti), to the solver's
    tolerance; the consistent loads sum to the surface's force."""
    mesh, field, probe, ports, X_SR = pad
    problem, fields, surface, readings = _readings(mesh, field, probe, ports, X_SR)
    assert not bool(surface.did_overflow) and int(surface.num_polygons) > 10
    loads = elastic.calc_surface_loads(problem, surface)
    np.testing.assert_allclose(np.asarray(jnp.sum(loads, axis=0)), np.asarray(surface.calc_force()), rtol=1e-12)
    direct = elastic.solve_elasticity(problem, loads, rtol=1e-12)
    expected = elastic.calc_port_readings(problem, direct.displacements, ports)
    np.testing.assert_allclose(np.asarray(readings), np.asarray(expected), rtol=1e-8)
    assert np.all(np.asarray(readings)[[0, 2]] > 0.0)  # compression under the press
    assert float(fields.relative_residual) < 1e-9


def _central(f, x, step):
    """The central difference of f at x along `step` (a scalar or a vector), per unit step."""
    return (f(x + step) - f(x - step)) / (2.0 * float(np.linalg.norm(step)))


def test_readings_gradients_match_central_differences(pad):
    """d reading / d (pose, nu, a port's position, a port's axis) by the implicit
    adjoint against central differences."""
    from hydrotact.contact import calc_contact_surface, make_pose

    mesh, field, probe, ports, X_SR = pad
    problem = elastic.make_elastic_problem(mesh, 0.49)
    capacity = _capacity()
    translation = np.asarray(X_SR.translation)

    # Jitted: run eagerly, each of the twelve differences traced and compiled the
    # solver's loop anew.
    @functools.partial(jax.jit, static_argnums=4)
    def reading(translation, nu, position, axis, channel):
        moved = eqx_tree_at_ports(ports, position, axis, channel)
        fields = elastic.calc_receptive_fields(problem, moved, poisson_ratio=nu, rtol=1e-12)
        surface = calc_contact_surface(field, probe, make_pose(translation), capacity)
        return jnp.where(surface.did_overflow, jnp.nan, elastic.calc_elastic_readings(fields, surface)[channel])

    args = (jnp.asarray(translation), jnp.asarray(0.49), jnp.asarray(ports.positions_S[1]), jnp.asarray(ports.axes_S[1]))
    grads = jax.grad(reading, argnums=(0, 1, 2, 3))(*args, 1)
    e = np.eye(3)
    for k, step in ((0, 1e-7), (2, 1e-7)):
        fd = _central(lambda t: float(reading(t, args[1], args[2], args[3], 1)), args[0], step * e[k])
        np.testing.assert_allclose(float(grads[0][k]), fd, rtol=2e-5)
    fd_nu = _central(lambda nu: float(reading(args[0], nu, args[2], args[3], 1)), 0.49, 1e-6)
    np.testing.assert_allclose(float(grads[1]), fd_nu, rtol=1e-5)
    for k in (0, 2):
        fd = _central(lambda p: float(reading(args[0], args[1], p, args[3], 1)), args[2], 1e-7 * e[k])
        np.testing.assert_allclose(float(grads[2][k]), fd, rtol=1e-5)
    fd_axis = _central(lambda a: float(reading(args[0], args[1], args[2], a, 1)), args[3], 1e-6 * e[0])
    np.testing.assert_allclose(float(grads[3][0]), fd_axis, rtol=1e-5)


def test_field_derivatives_match_central_differences_of_the_fields(pad):
    """The fields' derivatives along a port's position and axis (one solve each, what
    a layout design linearises with) against central differences of the solved fields,
    seen through a fixed random weighting of every node; a pressure port's axis
    changes nothing."""
    mesh, _, _, ports, _ = pad
    problem = elastic.make_elastic_problem(mesh, 0.49)
    derivatives = elastic.calc_field_derivatives(problem, ports, rtol=1e-12)
    assert derivatives.positions.shape == (problem.num_nodes, 4, 3, 3) and float(derivatives.relative_residual) < 1e-10
    weights = jnp.asarray(np.random.default_rng(3).normal(size=(problem.num_nodes, 3)))
    e = np.eye(3)

    def seen(position, axis, channel):
        fields = elastic.calc_receptive_fields(problem, eqx_tree_at_ports(ports, position, axis, channel), rtol=1e-12)
        return float(jnp.sum(weights * fields.responses[:, channel]))

    for channel in (0, 1):
        position, axis = jnp.asarray(ports.positions_S[channel]), jnp.asarray(ports.axes_S[channel])
        for k in (0, 2):
            fd = _central(lambda p, a=axis, c=channel: seen(p, a, c), position, 2e-7 * e[k])
            np.testing.assert_allclose(float(jnp.sum(weights * derivatives.positions[:, channel, :, k])), fd, rtol=1e-5)
        fd_axis = _central(lambda a, p=position, c=channel: seen(p, a, c), axis, 1e-6 * e[0])
        np.testing.assert_allclose(float(jnp.sum(weights * derivatives.axes[:, channel, :, 0])), fd_axis, rtol=1e-5, atol=1e-9 * abs(fd_axis) + 1e-12)
    assert float(jnp.max(jnp.abs(derivatives.axes[:, 0]))) == 0.0 and float(jnp.max(jnp.abs(derivatives.axes[:, 1]))) > 0.0


def eqx_tree_at_ports(ports, position, axis, channel):
    import equinox as eqx

    return eqx.tree_at(
        lambda p: (p.positions_S, p.axes_S), ports, (jnp.asarray(ports.positions_S).at[channel].set(position), jnp.asarray(ports.axes_S).at[channel].set(axis))
    )


# -------------------------------------------------------------- in the forward model


def _pad_document(kinds):
    """pad5x5 at 2.2 mm cells, its barometers of the given receptive-field kinds."""
    from hydrotact.sensors._builtins import builtin_documents

    document = builtin_documents()["pad5x5"]
    document["name"] = "coarse-pad"
    document["geometry"]["edge_length"] = 2.2
    document["elastomer"] = {"poisson_ratio": 0.48}
    for taxel, kind in zip(document["taxels"], kinds, strict=True):
        if kind == "elastic":
            taxel["receptive_field"] = {"kind": "elastic", "port_radius": 0.6, "reading": "pressure"}
    return document


def test_elastic_barometers_in_the_forward_model(tmp_path, monkeypatch):
    """A sensor file with elastic barometers: read back equal, simulated through the
    one forward model. A press at the pad's centre moves every elastic channel (the
    stress spreads through the rubber; a disk under the same press sees nothing past
    its radius), the nearest most; readings scale with E; the disk channels of a mixed
    sensor read what they read on an all-disk sensor; the fields come from the cache
    the second time."""
    from hydrotact.contact import make_sphere_probe
    from hydrotact.sensors import load_sensor
    from hydrotact.sim import make_sensor_model, make_trajectory, simulate
    from hydrotact.visco import make_prony

    monkeypatch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path / "cache"))  # the fields are solved here first
    kinds = ["elastic" if k % 2 == 0 else "disk" for k in range(25)]
    spec = load_sensor(_pad_document(kinds))
    assert spec.poisson_ratio == 0.48 and spec.is_elastic.sum() == 13
    again = load_sensor(spec.to_json())
    assert again.to_json() == spec.to_json() and again.taxel_elastic_readings == spec.taxel_elastic_readings
    np.testing.assert_allclose(again.taxel_field_sizes[0], 0.6e-3)

    probe = make_sphere_probe(3e-3, subdivisions=2)
    depths = np.array([0.0, 0.2e-3, 0.45e-3])
    trajectory = make_trajectory(np.arange(3) * 0.01, np.stack([np.full(3, 0.1e-3), np.full(3, -0.05e-3), 4e-3 - depths], axis=1))
    mixed = make_sensor_model(spec)
    assert mixed.uses_rays and mixed.elastic.num_barometers == 13
    samples = simulate(mixed, make_prony(1e5), probe, trajectory, cache=False)
    pressures = np.asarray(samples.taxel_pressures)
    assert np.all(pressures[0] == 0.0)
    # Its log names the stress-reading channels (their elastic readings may be tension).
    from hydrotact.sim import make_barometer_log

    log = make_barometer_log(spec, samples, trajectory, probe="sphere:r=3mm,subdivisions=2", material=make_prony(1e5))
    assert log.metadata["stress_channels"] == [name for name, kind in zip(spec.taxel_names, kinds) if kind == "elastic"]
    elastic_readings = pressures[2, spec.is_elastic]
    assert np.all(elastic_readings > 0.0)
    assert np.argmax(pressures[2]) == 12  # b22, under the press
    disks = make_sensor_model(load_sensor(_pad_document(["disk"] * 25)))
    disk_samples = simulate(disks, make_prony(1e5), probe, trajectory, cache=False)
    np.testing.assert_allclose(pressures[:, ~spec.is_elastic], np.asarray(disk_samples.taxel_pressures)[:, ~spec.is_elastic], rtol=1e-12, atol=0.0)
    assert np.sum(np.asarray(disk_samples.taxel_pressures)[2] > 0.0) < 13  # a disk sees only what lies over it
    stiffer = simulate(mixed, make_prony(2e5), probe, trajectory, cache=False)
    np.testing.assert_allclose(np.asarray(stiffer.taxel_pressures), 2.0 * pressures, rtol=1e-12)

    from hydrotact.elastic import _cache

    calls = []
    original = _cache._solve_fields
    try:
        _cache._solve_fields = lambda *args, **kwargs: calls.append(1) or original(*args, **kwargs)
        all_elastic = load_sensor(_pad_document(["elastic"] * 25))
        first = make_sensor_model(all_elastic)
        assert not first.uses_rays
        from hydrotact.sim import _model

        _model._MODELS.clear()
        second = make_sensor_model(all_elastic)
    finally:
        _cache._solve_fields = original
    assert len(calls) == 1
    np.testing.assert_array_equal(np.asarray(first.elastic.responses), np.asarray(second.elastic.responses))
    # the elastic channels of the mixed sensor are those of the all-elastic one
    all_samples = simulate(second, make_prony(1e5), probe, trajectory, cache=False)
    np.testing.assert_allclose(np.asarray(all_samples.taxel_pressures)[:, spec.is_elastic], pressures[:, spec.is_elastic], rtol=1e-6)


@pytest.mark.parametrize("name", ["sphere8", "ellipsoid8"])
def test_the_curved_sensors_have_no_blind_patch_under_the_elastic_model(name, monkeypatch, tmp_path):
    """sphere8 and ellipsoid8 as built in (elastic barometers): every touchable
    skin point (uniform by area), pressed along its inward normal by the dataset
    generator's 3 mm sphere and read at 0.5 N, moves at least two channels by more
    than 3 noise stds of the part, and every channel moves somewhere (the cones left
    17.6 % of sphere8's skin to none and b5, b7 to nothing). The fields are the
    shipped ones: nothing is solved."""
    from hydrotact.contact import parse_probe
    from hydrotact.datasets import PoseEngine, find_touchable_skin, pressing_rotation_vectors, sample_skin_points
    from hydrotact.elastic import _cache
    from hydrotact.sensors import load_sensor
    from hydrotact.sim import make_sensor_model

    monkeypatch.setattr(_cache, "_solve_fields", lambda *args, **kwargs: pytest.fail("the shipped fields were not found"))
    monkeypatch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path))  # no field solved before can be read
    spec = load_sensor(name)  # elastic barometers by default
    model = make_sensor_model(spec, num_rays=1)
    assert not model.uses_rays and model.elastic.num_barometers == 8
    skin = find_touchable_skin(spec, spec.make_mesh(check=False))
    points, normals, _ = sample_skin_points(skin, 48, np.random.default_rng(7))
    depth = 0.3e-3
    rows = np.column_stack([points - depth * normals, pressing_rotation_vectors(-normals)])
    unit = PoseEngine(model, parse_probe("sphere:r=3mm,subdivisions=2")).compute(rows)
    force = np.einsum("ij,ij->i", unit["force_S"], -normals)  # per pascal of E, along the press
    assert np.all(force > 0.0)
    readings = unit["taxel_pressures"] * (0.5 / force)[:, None]  # Pa at 0.5 N: the response is linear in E
    moving = np.abs(readings) > 3.0 * spec.part.noise_rms_pa
    assert moving.sum(axis=1).min() >= 2, np.flatnonzero(moving.sum(axis=1) < 2)
    assert moving.any(axis=0).all(), np.flatnonzero(~moving.any(axis=0))


def test_matrix_free_stiffness_equals_the_assembled_blocks():
    """K u applied tet by tet equals the assembled block matrix's product, and its
    diagonal blocks are the assembled ones (two implementations agree)."""
    from hydrotact.elastic._problem import calc_diagonal_blocks, calc_reduced_system
    from hydrotact.elastic._quadratic import apply_blocks

    mesh = make_box((3e-3, 2e-3, 2e-3), 1e-3)
    problem = elastic.make_elastic_problem(mesh, 0.47)
    vertices = jnp.asarray(problem.vertices) + 1e-4 * jnp.asarray(np.random.default_rng(1).normal(size=problem.vertices.shape))
    u = jnp.asarray(np.random.default_rng(2).normal(size=(problem.num_nodes, 3)))
    _, _, stiffness = calc_reduced_system(problem, vertices, 0.47, 3.0)
    values = elastic.calc_stiffness_blocks(problem, vertices, 0.47, 3.0)
    expected = apply_blocks(problem.pattern, values, u)
    np.testing.assert_allclose(np.asarray(stiffness(u)), np.asarray(expected), rtol=1e-12, atol=1e-12 * float(jnp.abs(expected).max()))
    diagonal = values.reshape(-1, 3, 3)[np.asarray(problem.pattern.diagonal)]
    np.testing.assert_allclose(np.asarray(calc_diagonal_blocks(problem, vertices, 0.47, 3.0)), np.asarray(diagonal), rtol=1e-12, atol=1e-12 * float(jnp.abs(diagonal).max()))


def test_multigrid_preconditioner_gives_the_same_solution_and_gradients_in_fewer_steps():
    """CG preconditioned by the smoothed-aggregation V-cycle converges to the block
    Jacobi solution in a fraction of the steps, and the gradient of a reading in nu
    and in the loads through it is the same (the preconditioner is a constant)."""
    mesh = make_box((8e-3, 8e-3, 4e-3), 0.8e-3)
    problem = elastic.make_elastic_problem(mesh, 0.49)
    quadrature = elastic.make_face_quadrature(problem, mesh.faces_tagged(FREE))
    multigrid = elastic.make_multigrid_preconditioner(problem)
    assert multigrid.num_levels >= 2
    ports = elastic.make_barometer_ports([[0.4e-3, -0.3e-3, 0.5e-3]], [[0.0, 0.0, 1.0]])
    centre = np.exp(-np.sum(np.asarray(quadrature.points_S)[:, :2] ** 2, axis=1) / (2 * 1e-3**2))

    def reading(nu, scale, multigrid):
        tractions = -scale * jnp.asarray(centre)[:, None] * jnp.asarray([0.2, 0.0, 1.0])[None]
        loads = elastic.calc_face_loads(problem, quadrature, tractions)
        solution = elastic.solve_elasticity(problem, loads, poisson_ratio=nu, multigrid=multigrid, rtol=1e-12)
        return elastic.calc_port_readings(problem, solution.displacements, ports, poisson_ratio=nu)[0], solution.num_steps

    value_and_grad = eqx.filter_jit(jax.value_and_grad(reading, argnums=(0, 1), has_aux=True))
    (value, steps), grads = value_and_grad(jnp.asarray(0.49), jnp.asarray(1.0), multigrid)
    (plain, plain_steps), plain_grads = value_and_grad(jnp.asarray(0.49), jnp.asarray(1.0), None)
    assert int(steps) * 4 < int(plain_steps), (int(steps), int(plain_steps))
    np.testing.assert_allclose(float(value), float(plain), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(grads), np.asarray(plain_grads), rtol=1e-7)
    np.testing.assert_allclose(float(grads[1]), float(value), rtol=1e-9)  # linear in the load


def test_design_refuses_a_mixed_sensor_with_one_line():
    """A design moves elastic barometers or ray-cast taxels, not both at once: a sensor
    with some of each is refused before any work, naming the elastic ones."""
    from hydrotact import HydrotactError
    from hydrotact.design import DesignConfig, design_layout
    from hydrotact.sensors import load_sensor

    kinds = ["elastic" if k in (3, 7) else "disk" for k in range(25)]
    with pytest.raises(HydrotactError, match="only barometers b03, b12 are elastic"):
        design_layout(load_sensor(_pad_document(kinds)))
    with pytest.raises(HydrotactError, match="--field-sizes"):
        design_layout(load_sensor(_pad_document(["elastic"] * 25)), config=DesignConfig(field_sizes=True))


def test_the_linearised_readout_is_exact_at_its_expansion_and_second_order_beside(pad):
    """A design's readout of elastic barometers at its expansion equals the readings
    from the fields, and moved by h along a port's position or a normal-stress port's
    axis it differs from the exact readings (solved anew) by O(h^2): the error falls
    by 4 when h halves."""
    from hydrotact.contact import calc_contact_surface, make_pose, make_sphere_probe
    from hydrotact.design._elastic import ElasticDesigner

    mesh, field, _, ports, X_SR = pad
    probe = make_sphere_probe(3e-3, subdivisions=1)  # the coarse sphere (fewer polygons)
    contacts = _pad_contacts(probe, [np.asarray(X_SR.translation), np.asarray(X_SR.translation) + [1.1e-3, 0.4e-3, 0.0]])
    radii, readings = np.asarray(ports.port_radii), ["normal_stress" if n else "pressure" for n in np.asarray(ports.reads_normal_stress)]
    designer = ElasticDesigner(mesh, 0.49, radii, readings)
    positions, axes = np.asarray(ports.positions_S), np.asarray(ports.axes_S)
    readout = designer.readout(positions, axes, contacts)
    surface = calc_contact_surface(field, probe, make_pose(np.asarray(X_SR.translation)), _capacity())
    fields = elastic.calc_receptive_fields(elastic.make_elastic_problem(mesh, 0.49), ports, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(readout.tau[0]), np.asarray(elastic.calc_elastic_readings(fields, surface)) / 1e5, rtol=1e-7)
    for name, move in (("position", np.array([0.4e-3, -0.3e-3, 0.2e-3])), ("axis", np.array([0.12, -0.08, 0.0]))):
        errors = []
        for h in (1.0, 0.5):
            moved_positions = positions + (h * move if name == "position" else 0.0)
            moved_axes = axes + (h * move if name == "axis" else 0.0)
            moved_axes = moved_axes / np.linalg.norm(moved_axes, axis=1, keepdims=True)
            linear, _ = readout.at(jnp.asarray(moved_positions), jnp.asarray(moved_axes))
            exact = designer.readout(moved_positions, moved_axes, contacts, derivatives=False).tau
            errors.append(float(jnp.max(jnp.abs(linear - exact)[:, 1 if name == "axis" else slice(None)])))
        assert errors[1] < 0.35 * errors[0], (name, errors)


def _pad_contacts(probe, translations):
    """DesignContacts of the probe pressed straight down to the given translations on
    the coarse pad (its unit surfaces are per pascal of E)."""
    from hydrotact.design._contacts import linearise_contacts
    from hydrotact.sensors import load_sensor
    from hydrotact.sim import make_sensor_model

    model = make_sensor_model(load_sensor(_pad_document(["disk"] * 25)), num_rays=1)
    points = np.array([[t[0], t[1], 4e-3] for t in translations])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    depths = np.array([4e-3 - t[2] for t in translations])
    return linearise_contacts(model, probe, 1e5, points, normals, np.ones(len(points)), np.full(len(points), 2e-3), np.zeros((len(points), 3)), target_depths=depths)


def test_design_moves_elastic_barometers_through_their_fields(tmp_path):
    """`hydrotact design` of a pad whose barometers are all elastic: the layout moves
    (rounds on the linearised readings, each solved exactly), its exact score only
    rises over the rounds, the designed sensor is feasible, elastic, reads as the
    start did, and scores at least as well as its start on the design's contacts."""
    import json

    from hydrotact.cli import main
    from hydrotact.sensors import load_sensor

    sensor = tmp_path / "pad.json"
    sensor.write_text(json.dumps(_pad_document(["elastic"] * 25)))
    output = tmp_path / "designed.json"
    status = main([
        "design", "--sensor", str(sensor), "--barometers", "4", "--contacts", "16", "--restarts", "1", "--steps", "8", "--expansions", "2",
        "--probe", "sphere:r=3mm,subdivisions=1", "--target", "depth", "--depth-range", "0.0003,0.0008", "-o", str(output), "--json",
    ])
    assert status == 0
    designed = load_sensor(output)
    assert designed.is_elastic.all() and designed.num_taxels == 4 and designed.taxel_elastic_readings == ("pressure",) * 4
    np.testing.assert_allclose(designed.taxel_field_sizes, 0.6e-3)
    assert np.allclose(designed.taxel_positions_S[:, 2], 0.0, atol=1e-9)  # on the board, as the pad's own
    report = json.loads((tmp_path / "designed_report.json").read_text())
    start, final = report["random_starts"][0], report["scores"]["designed"]
    assert final["score"] > start["score"], (start, final)  # a round was kept: it scored better, exactly


def test_a_jittered_layout_solves_the_moved_ports_fields(tmp_path, monkeypatch):
    """The dataset generator's casting tolerance (`--position-jitter`) on a sensor with
    elastic barometers: every barometer moves, and each elastic one reads through the
    field of its moved port, the same as a sensor built with its barometers there; an
    unmoved layout solves nothing. (On a coarse pad with two elastic barometers: on
    sphere8 the eight fields take minutes, so the fine-tuning tests and the
    experiment's smoke run leave sphere8's barometers in place.)"""
    from hydrotact.datasets._generate import _jitter_layout
    from hydrotact.sensors import load_sensor
    from hydrotact.sim import make_sensor_model

    monkeypatch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path / "cache"))
    document = _pad_document(["elastic" if k in (6, 12) else "disk" for k in range(25)])
    spec = load_sensor(document)
    model = make_sensor_model(spec, num_rays=8)
    fields = lambda: sorted((tmp_path / "cache" / "elastic_fields").glob("*.npz"))
    solved = fields()
    same, offsets = _jitter_layout(model, spec, 0.0, np.random.default_rng(0))
    assert same is model and not np.any(offsets) and fields() == solved
    # seed 1: both elastic ports move up, into the rubber (a port pushed below the
    # board face would be outside the elastomer, which a sensor file refuses)
    jittered, offsets = _jitter_layout(model, spec, 0.3e-3, np.random.default_rng(1))
    assert np.all(np.abs(offsets) > 0.0) and np.all(offsets[[6, 12], 2] > 0.0)
    assert len(fields()) == len(solved) + 2  # the two moved ports, solved
    np.testing.assert_allclose(np.asarray(jittered.layout.positions_S), spec.taxel_positions_S + offsets, rtol=0, atol=1e-15)
    for k in (6, 12):  # a sensor file with the elastic barometers where the jitter put them
        document["taxels"][k]["position"] = list(np.asarray(document["taxels"][k]["position"]) + offsets[k] * 1e3)  # mm
    moved = make_sensor_model(load_sensor(document), num_rays=8)
    assert len(fields()) == len(solved) + 2  # the same ports: read from the cache
    np.testing.assert_allclose(np.asarray(jittered.elastic.responses), np.asarray(moved.elastic.responses), rtol=0, atol=0)
    assert not np.allclose(np.asarray(jittered.elastic.responses), np.asarray(model.elastic.responses))


def test_a_pressurised_spherical_cavity_converges_to_lames_compliance():
    """A pocket's compliance C (its volume per unit pressure at E = 1 Pa) on a hollow
    ball fixed on its outer sphere, against Lamé's closed form (u = A r + B / r²):
    second order in the mesh size, the polyhedral sphere's own order."""
    a, b, nu = 2e-3, 6e-3, 0.45
    lam, mu = nu / ((1 + nu) * (1 - 2 * nu)), 1.0 / (2 * (1 + nu))
    B = 1.0 / ((3 * lam + 2 * mu) / b**3 + 4 * mu / a**3)
    exact = 4 * np.pi * a**2 * B * (1 / a**2 - a / b**3)
    errors = []
    for layers in (2, 3):
        shell = make_spherical_shell(a, b, layers)  # its inner sphere core, its outer free: swapped
        tags = np.asarray(shell.face_tags)
        shell = eqx.tree_at(lambda m: m.face_tags, shell, jnp.asarray(np.where(tags == CORE, FREE, CORE)))
        faces = elastic.find_cavity_faces(shell, [0.0, 0.0, 0.0])  # the void: every free face
        np.testing.assert_allclose(elastic.calc_cavity_volume(shell, faces), 4 / 3 * np.pi * a**3, rtol=0.2)  # its polyhedron's
        cavity = elastic.calc_cavity_fields(elastic.make_elastic_problem(shell, nu), [faces], rtol=1e-10)
        errors.append(abs(float(cavity.compliances[0]) / exact - 1.0))
    order = np.log(errors[0] / errors[1]) / np.log(3 / 2)
    assert errors[1] < 0.05 and 1.7 < order < 3.0, (errors, order)


def test_a_pocket_barometer_reads_the_pressure_that_holds_its_volume(tmp_path):
    """A strip cast over a 2 x 2 x 1 mm pocket (a tray's floor former): pressed on the
    skin above it, the pocket's rubber squeezes its air. Its reading by reciprocity is
    the pressure that, added on the pocket's faces, leaves its volume unchanged (a
    direct solve with both loads), positive, and larger over the pocket than 4 mm
    off it; the rubber's own stress at the pocket's ceiling (an `elastic` port there)
    is tension. A port on the skin is no pocket."""
    from helpers import write_mould

    from hydrotact import HydrotactError
    from hydrotact.mesh import load_tet_mesh

    tray = write_mould(tmp_path / "tray.stl", ((0, 0, 0), (16, 8, 6)), [((2, 2, 2), (14, 6, 6.5))], formers=[((7, 3, 2), (9, 5, 3))])
    cast = load_tet_mesh([str(tray)], units="mm", edge_length=1.0)  # 12 x 4 x 4 mm, the pocket at the floor's centre
    faces = elastic.find_cavity_faces(cast, [0.0, 0.0, 1e-3])
    corners = np.asarray(cast.vertices)[faces]
    area = 0.5 * np.sum(np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1))
    np.testing.assert_allclose(area, 12e-6, rtol=0.02)  # the ceiling 2 x 2 and four walls 2 x 1 mm
    np.testing.assert_allclose(elastic.calc_cavity_volume(cast, faces), 4e-9, rtol=0.03)
    with pytest.raises(HydrotactError, match="not in a pocket"):
        elastic.find_cavity_faces(cast, [0.0, 0.0, 4e-3])
    problem = elastic.make_elastic_problem(cast, 0.45)
    cavity = elastic.calc_cavity_fields(problem, [faces], rtol=1e-11)
    volume_loads = cavity.volume_loads[0]
    top = np.asarray(cast.boundary_faces)[np.asarray(cast.face_tags) == FREE]
    top_corners = np.asarray(cast.vertices)[top]
    on_skin = np.all(np.abs(top_corners[..., 2] - 4e-3) < 1e-5, axis=1)

    def press(x):  # 1 kPa on the skin's faces within 1.5 mm of (x, 0)
        near = on_skin & np.all(np.abs(top_corners[..., 0] - x) < 1.5e-3, axis=1) & np.all(np.abs(top_corners[..., 1]) < 1.5e-3, axis=1)
        quadrature = elastic.make_face_quadrature(problem, top[near])
        return elastic.calc_face_loads(problem, quadrature, -1e3 * jnp.asarray(quadrature.normals_S))

    readings = []
    for x in (0.0, 4e-3):
        loads = press(x)
        squeezed = float(jnp.sum(volume_loads * elastic.solve_elasticity(problem, loads, rtol=1e-11).displacements))
        reading = float(jnp.sum(loads * cavity.fields.responses[:, 0, :]))
        np.testing.assert_allclose(reading, -squeezed / float(cavity.compliances[0]), rtol=1e-8)
        held = elastic.solve_elasticity(problem, loads + reading * volume_loads, rtol=1e-11).displacements
        assert abs(float(jnp.sum(volume_loads * held))) < 1e-7 * abs(squeezed)  # the pocket keeps its volume
        readings.append(reading)
    assert readings[0] > 2.0 * readings[1] > 0.0
    # With 4 mm³ of air in E = 1 MPa rubber: the air's law p = -K_a dV / V0 holds in a
    # direct solve with the loads scaled to E and the pocket's pressure on its faces.
    modulus, air = 1e6, 4e-9
    reading = readings[0] * float(elastic.calc_air_factor(cavity.compliances[0], modulus, air))
    grown = float(jnp.sum(volume_loads * elastic.solve_elasticity(problem, press(0.0) + reading * volume_loads, modulus=modulus, rtol=1e-11).displacements))
    np.testing.assert_allclose(reading, -elastic.AIR_MODULUS * grown / air, rtol=1e-7)
    assert 0.0 < reading < 0.5 * readings[0]
    ceiling = elastic.make_barometer_ports([[0.0, 0.0, 1e-3]], [[0.0, 0.0, 1.0]], [0.3e-3])
    direct = elastic.solve_elasticity(problem, press(0.0), rtol=1e-11)
    assert float(elastic.calc_port_readings(problem, direct.displacements, ceiling)[0]) < 0.0
    # A sensor's `cavity` barometer gets this field (found from its port, cached by its
    # pocket, no derivatives: the pocket does not move with the port); one on the skin
    # is refused, naming it.
    fields = elastic.make_receptive_fields(cast, [[0.1e-3, 0.0, 1e-3]], [[0.0, 0.0, 1.0]], [0.5e-3], ["cavity"], 0.45, cache=False)
    np.testing.assert_allclose(np.asarray(fields.responses), np.asarray(cavity.fields.responses), rtol=1e-6, atol=1e-9 * float(jnp.max(jnp.abs(cavity.fields.responses))))
    moved = elastic.make_field_derivatives(cast, [[0.1e-3, 0.0, 1e-3]], [[0.0, 0.0, 1.0]], [0.5e-3], ["cavity"], 0.45, cache=False)
    assert not np.any(np.asarray(moved.positions)) and not np.any(np.asarray(moved.axes))
    with pytest.raises(HydrotactError, match="barometer 1: the barometer at .* is not in a pocket"):
        elastic.make_receptive_fields(cast, [[0.0, 0.0, 1e-3], [0.0, 0.0, 4e-3]], [[0.0, 0.0, 1.0]] * 2, [0.5e-3] * 2, ["cavity"] * 2, 0.45, cache=False)
