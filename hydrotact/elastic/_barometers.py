"""What a barometer cast in the elastomer reads, and its receptive field by reciprocity.

A MEMS barometer's membrane sits under a port filled with the elastomer: it reads the
pressure of the elastomer at the port. By default that is the hydrostatic pressure
p = -tr(sigma) / 3 (what a fluid-like, nearly incompressible silicone transmits to a
membrane whatever its orientation), averaged over the port: the mean weighted by the
Gaussian exp(-|y - x|^2 / (2 r^2)) over the elastomer, x the port's position and r its
radius (each tet's weight the Gaussian integrated over it by its four-point rule;
smooth in x, so a layout can be designed by gradient). Optionally the barometer reads the compressive normal stress
along its axis a, -a . sigma . a (a stiff membrane loaded by the normal traction
alone), from each tet's stress at its centroid. Both are positive in compression,
like the contact pressure, and both are linear in the displacement u: reading = g . u.

Reciprocity (Maxwell-Betti): with K u = f, reading = g . K^{-1} f = f . w with
K w = g (K is symmetric). So one solve per barometer gives w, its *receptive field*:
the reading caused by a unit force at any point of the elastomer (interpolated with
the P2 shape functions). A contact surface's tractions p n (the pressure pushing the
elastomer along the polygon's normal) are then integrated against w exactly (p is
linear and w quadratic over each polygon: the six-point triangle rule on the
polygon's fan is exact), and the reading needs no solve per pose.

Units: with the stiffness at E = 1 Pa, w is per newton (Pa / N) and independent of E:
under prescribed forces the stress depends only on nu and the geometry. Readings are
therefore linear in the contact pressure and so in the hydroelastic modulus, and a
viscoelastic material acts on them as on every other unit response (a Prony shear
modulus at constant nu: the correspondence principle leaves the stress of a
traction-loaded body unchanged, so the readings relax with the contact pressure).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._choices import Choice
from .._defaults import DEFAULT_PORT_RADIUS
from .._errors import HydrotactError
from .._math import safe_norm
from .._types import Array, Bool, Float, Int
from ..field import calc_tet_gradients
from ._loads import TRIANGLE_QUADRATURE, TRIANGLE_WEIGHTS
from ._problem import (
    TET_QUADRATURE,
    ElasticProblem,
    _default_rtol,
    calc_element_operators,
    calc_lame,
    solve_reduced,
)
from ._quadratic import calc_shape_functions, calc_shape_gradients


class ElasticReading(Choice):
    """What an elastic barometer reads: `pressure`, the hydrostatic pressure
    -tr(sigma) / 3 at its port (the default), `normal_stress`, the compressive normal
    stress along its axis, or `cavity`, the air sealed in the pocket its port is in
    (:mod:`hydrotact.elastic._cavity`: the pressure that holds the pocket's volume)."""

    PRESSURE = "pressure"
    NORMAL_STRESS = "normal_stress"
    CAVITY = "cavity"


class BarometerPorts(eqx.Module):
    """Where elastic barometers read the elastomer (a pytree; differentiable in every
    float field).

    **Fields:** `positions_S` (B, 3) m; `axes_S` (B, 3) (normalised where used);
    `port_radii` (B,) m; `reads_normal_stress` (B,) True for `normal_stress`.
    """

    positions_S: Float[Array, "num_barometers 3"]
    axes_S: Float[Array, "num_barometers 3"]
    port_radii: Float[Array, " num_barometers"]
    reads_normal_stress: Bool[Array, " num_barometers"]

    @property
    def num_barometers(self) -> int:
        return self.positions_S.shape[0]


def make_barometer_ports(positions_S, axes_S, port_radii=None, readings=None) -> BarometerPorts:
    """BarometerPorts from host arrays, checked (positive radii, non-zero axes)."""
    positions = np.asarray(positions_S, dtype=np.float64).reshape(-1, 3)
    axes = np.asarray(axes_S, dtype=np.float64).reshape(-1, 3)
    count = len(positions)
    radii = np.full(count, DEFAULT_PORT_RADIUS) if port_radii is None else np.asarray(port_radii, dtype=np.float64).reshape(-1)
    kinds = [ElasticReading.PRESSURE] * count if readings is None else [ElasticReading.parse(k, "elastic reading") for k in readings]
    if axes.shape != (count, 3) or radii.shape != (count,) or len(kinds) != count:
        raise HydrotactError(f"barometer ports: {count} positions, {len(axes)} axes, {len(radii)} radii and {len(kinds)} readings differ")
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(axes))):
        raise HydrotactError("barometer ports: positions and axes must be finite")
    norms = np.linalg.norm(axes, axis=1)
    if np.any(norms == 0.0):
        raise HydrotactError(f"barometer port {int(np.argmin(norms))}: the axis is zero")
    if not np.all(np.isfinite(radii) & (radii > 0.0)):
        raise HydrotactError(f"barometer port {int(np.argmin(np.isfinite(radii) & (radii > 0.0)))}: the port radius must be a positive length in metres")
    return BarometerPorts(
        positions_S=positions,
        axes_S=axes / norms[:, None],
        port_radii=radii,
        reads_normal_stress=np.array([k == ElasticReading.NORMAL_STRESS for k in kinds], dtype=bool),
    )


def calc_port_weights(vertices, tets, ports: BarometerPorts):
    """(B, num_tets) each port's weights over the tets, summing to 1: the Gaussian
    exp(-|x - x_b|^2 / (2 r_b^2)) integrated over each tet by its four-point rule,
    normalised (in log space, so a port far from every tet still gets finite weights)."""
    _, volumes = calc_tet_gradients(vertices, tets)
    points = jnp.einsum("qi,tid->tqd", jnp.asarray(TET_QUADRATURE, vertices.dtype), vertices[tets])  # (T, 4, 3)
    offsets = points[None] - ports.positions_S[:, None, None, :]
    squared = jnp.sum(offsets * offsets, axis=-1)  # (B, T, 4)
    logits = jnp.log(volumes / 4.0)[None, :, None] - squared / (2.0 * ports.port_radii[:, None, None] ** 2)
    per_tet = jax.scipy.special.logsumexp(logits, axis=-1)
    return jax.nn.softmax(per_tet, axis=-1)


def calc_port_readings(problem: ElasticProblem, displacements, ports: BarometerPorts, poisson_ratio=None, vertices=None, modulus=1.0):
    """What each barometer reads of a displacement field (B,), Pa (compression
    positive; pure, linear in `displacements` (num_nodes, 3))."""
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    nu = problem.poisson_ratio if poisson_ratio is None else poisson_ratio
    mu, kappa = calc_lame(modulus, nu)
    _, _, mean_gradients = calc_element_operators(problem, vertices)
    element_u = displacements[problem.tet_nodes]  # (T, 10, 3)
    pressures = -kappa * jnp.einsum("tad,tad->t", mean_gradients, element_u)
    lambda_gradients, _ = calc_tet_gradients(vertices, problem.tets)
    centroid = jnp.full((1, 4), 0.25, vertices.dtype)
    gradients = calc_shape_gradients(centroid, lambda_gradients)  # (T, 10, 3)
    grad_u = jnp.einsum("tak,tal->tkl", element_u, gradients)
    strain = 0.5 * (grad_u + jnp.swapaxes(grad_u, -1, -2))
    trace = jnp.trace(strain, axis1=-2, axis2=-1)
    axes = ports.axes_S / safe_norm(ports.axes_S, axis=1, keepdims=True)
    along = jnp.einsum("bk,tkl,bl->bt", axes, strain, axes)
    # -a . sigma . a = p - 2 mu (a . eps a - tr(eps) / 3)
    normal = pressures[None, :] - 2.0 * mu * (along - trace[None, :] / 3.0)
    element_readings = jnp.where(ports.reads_normal_stress[:, None], normal, pressures[None, :])
    weights = calc_port_weights(vertices, problem.tets, ports)
    return jnp.sum(weights * element_readings, axis=-1)


class ReceptiveFields(eqx.Module):
    """Elastic barometers' receptive fields: the reading per newton of a force at
    each P2 node (a pytree).

    **Fields:**

    - `vertices`, `tets`, `tet_nodes`: the mesh they live on (frame S).
    - `responses`: (num_nodes, B, 3) barometer b's reading for a unit force along
      each axis at each node, Pa / N.
    - `num_steps`, `relative_residual`: the worst of the B solves.
    """

    vertices: Float[Array, "num_vertices 3"]
    tets: Int[Array, "num_tets 4"]
    tet_nodes: Int[Array, "num_tets 10"]
    responses: Float[Array, "num_nodes num_barometers 3"]
    num_steps: Int[Array, ""]
    relative_residual: Float[Array, ""]

    @property
    def num_barometers(self) -> int:
        return self.responses.shape[1]


@eqx.filter_jit
def _fields(problem, ports, vertices, nu, rtol, max_steps, throw, multigrid):
    zeros = jnp.zeros((problem.num_nodes, 3), vertices.dtype)
    _, pullback = jax.vjp(lambda u: calc_port_readings(problem, u, ports, nu, vertices), zeros)
    eye = jnp.eye(ports.num_barometers, dtype=vertices.dtype)
    (functionals,) = jax.vmap(pullback)(eye)  # (B, num_nodes, 3): reading = g . u
    mask = (~problem.is_fixed).astype(vertices.dtype)[None, :, None]
    params = (vertices, nu, jnp.asarray(1.0, vertices.dtype))
    solve = jax.vmap(lambda rhs: solve_reduced(problem, params, rhs, rtol, max_steps, throw, multigrid))
    responses, num_steps, relative, result = solve(mask * functionals)
    return ReceptiveFields(
        vertices=vertices,
        tets=problem.tets,
        tet_nodes=problem.tet_nodes,
        responses=jnp.moveaxis(mask * responses, 0, 1),
        num_steps=jnp.max(num_steps),
        relative_residual=jnp.max(relative),
    ), result


def _solve_settings(problem, vertices, poisson_ratio, rtol, max_steps):
    """(vertices, nu, rtol, max_steps) of a solve, the problem's where not given."""
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    nu = jnp.asarray(problem.poisson_ratio if poisson_ratio is None else poisson_ratio, vertices.dtype)
    rtol = _default_rtol(vertices.dtype) if rtol is None else rtol
    max_steps = 20 * problem.num_nodes + 1000 if max_steps is None else max_steps
    return vertices, nu, rtol, max_steps


def calc_receptive_fields(
    problem: ElasticProblem,
    ports: BarometerPorts,
    *,
    poisson_ratio=None,
    vertices=None,
    rtol: float | None = None,
    max_steps: int | None = None,
    throw: bool = True,
    multigrid=None,
) -> ReceptiveFields:
    """Every barometer's receptive field, one adjoint solve each (jittable;
    differentiable in the ports' positions, axes and radii, nu and the vertices).

    **Arguments:** `problem` from :func:`make_elastic_problem`; `ports` from
    :func:`make_barometer_ports`; the rest (`multigrid` too) as
    :func:`solve_elasticity`'s.
    """
    vertices, nu, rtol, max_steps = _solve_settings(problem, vertices, poisson_ratio, rtol, max_steps)
    fields, result = _fields(problem, ports, vertices, nu, rtol, max_steps, throw, multigrid)
    del result  # raised inside the solve when `throw`; per-solve codes are not kept
    return fields


class FieldDerivatives(eqx.Module):
    """How elastic barometers' receptive fields change as their ports move (a pytree):
    the derivatives of :attr:`ReceptiveFields.responses` (num_nodes, B, 3) along each
    port's position (`positions`, (num_nodes, B, 3, 3), the last axis the position's
    x, y, z; Pa / N / m) and its axis (`axes`, likewise, per unit of the axis vector
    as given, normalised inside; zero for a port reading the pressure, which no axis
    changes); `num_steps`, `relative_residual` the worst solve's."""

    positions: Float[Array, "num_nodes num_barometers 3 3"]
    axes: Float[Array, "num_nodes num_barometers 3 3"]
    num_steps: Int[Array, ""]
    relative_residual: Float[Array, ""]


@eqx.filter_jit
def _derivatives(problem, ports, vertices, nu, rtol, max_steps, throw, multigrid, with_axes: bool):
    zeros = jnp.zeros((problem.num_nodes, 3), vertices.dtype)

    def functionals(positions, axes):
        moved = eqx.tree_at(lambda p: (p.positions_S, p.axes_S), ports, (positions, axes))
        _, pullback = jax.vjp(lambda u: calc_port_readings(problem, u, moved, nu, vertices), zeros)
        return jax.vmap(pullback)(jnp.eye(ports.num_barometers, dtype=vertices.dtype))[0]  # (B, num_nodes, 3)

    count = ports.num_barometers
    eye = jnp.eye(3, dtype=vertices.dtype)
    along = jnp.concatenate([eye, jnp.zeros_like(eye)], axis=1)  # (3, 6): position, then axis components
    if with_axes:
        along = jnp.concatenate([along, jnp.concatenate([jnp.zeros_like(eye), eye], axis=1)])
    positions, axes = jnp.asarray(ports.positions_S, vertices.dtype), jnp.asarray(ports.axes_S, vertices.dtype)

    def tangent(direction):  # every port moved along the same direction at once: port b's functional depends on port b alone
        dp, da = jnp.broadcast_to(direction[:3], (count, 3)), jnp.broadcast_to(direction[3:], (count, 3))
        return jax.jvp(functionals, (positions, axes), (dp, da))[1]

    rhs = jax.vmap(tangent)(along)  # (K, B, num_nodes, 3)
    mask = (~problem.is_fixed).astype(vertices.dtype)[None, None, :, None]
    params = (vertices, nu, jnp.asarray(1.0, vertices.dtype))
    solve = jax.vmap(jax.vmap(lambda b: solve_reduced(problem, params, b, rtol, max_steps, throw, multigrid)))
    solved, num_steps, relative, result = solve(mask * rhs)
    solved = jnp.moveaxis(mask * solved, (0, 1), (-1, 1))  # (num_nodes, B, 3, K)
    axes_part = solved[..., 3:] if with_axes else jnp.zeros_like(solved)
    return FieldDerivatives(solved[..., :3], axes_part, jnp.max(num_steps), jnp.max(relative)), result


def calc_field_derivatives(
    problem: ElasticProblem,
    ports: BarometerPorts,
    *,
    poisson_ratio=None,
    vertices=None,
    rtol: float | None = None,
    max_steps: int | None = None,
    throw: bool = True,
    multigrid=None,
    with_axes: bool | None = None,
) -> FieldDerivatives:
    """The receptive fields' derivatives along every port's position and axis (one
    solve with the same operator per direction: the field is K^{-1} g(x, a), so its
    derivative is K^{-1} dg; three solves per port, six where `with_axes`, by default
    where any port reads the normal stress). What a layout design linearises the
    fields with. Arguments as :func:`calc_receptive_fields`'s (jittable)."""
    vertices, nu, rtol, max_steps = _solve_settings(problem, vertices, poisson_ratio, rtol, max_steps)
    with_axes = bool(np.any(np.asarray(ports.reads_normal_stress))) if with_axes is None else bool(with_axes)
    derivatives, result = _derivatives(problem, ports, vertices, nu, rtol, max_steps, throw, multigrid, with_axes)
    del result
    return derivatives


def calc_polygon_node_integrals(vertices, tets, surface):
    """For each contact polygon, the integrals int p N_a dA of its pressure against the
    ten shape functions of its tet, (capacity, 10), N (0 on invalid slots).

    Each polygon (convex, <= 8 vertices, inside its tet) is fanned from its first
    vertex into triangles, each integrated by the six-point rule (exact: p N_a is
    cubic)."""
    polygon = surface.vertices_S  # (C, 8, 3)
    pressures = surface.pressures  # (C, 8)
    k = jnp.arange(1, polygon.shape[1] - 1)  # fan triangles (0, k, k + 1)
    a, b, c = polygon[:, :1], polygon[:, 1:-1], polygon[:, 2:]  # (C, 1 | 6, 3)
    pa, pb, pc = pressures[:, :1], pressures[:, 1:-1], pressures[:, 2:]
    fan_valid = (k[None, :] + 1 < surface.counts[:, None]) & surface.valid[:, None]
    areas = 0.5 * safe_norm(jnp.cross(b - a, c - a), axis=-1)  # (C, 6)
    weights = jnp.where(fan_valid, areas, 0.0)[..., None] * jnp.asarray(TRIANGLE_WEIGHTS, polygon.dtype)[None, None]  # (C, 6, Q)
    q = jnp.asarray(TRIANGLE_QUADRATURE, polygon.dtype)  # (Q, 3)
    points = q[None, None, :, 0, None] * a[:, :, None] + q[None, None, :, 1, None] * b[:, :, None] + q[None, None, :, 2, None] * c[:, :, None]
    point_pressures = q[None, None, :, 0] * pa[..., None] + q[None, None, :, 1] * pb[..., None] + q[None, None, :, 2] * pc[..., None]
    tet_index = jnp.maximum(surface.tet_index, 0)
    num_points = points.shape[1] * points.shape[2]
    # Each polygon's tet once: lambda = e_0 + grad(lambda) . (x - x_0) at its points.
    lambda_gradients, _ = calc_tet_gradients(vertices, tets[tet_index])  # (C, 4, 3)
    origin = vertices[tets[tet_index, 0]]
    offsets = points.reshape(polygon.shape[0], num_points, 3) - origin[:, None, :]
    lam = jnp.einsum("cid,cqd->cqi", lambda_gradients, offsets)
    lam = lam + jnp.asarray([1.0, 0.0, 0.0, 0.0], lam.dtype)[None, None, :]
    shape = calc_shape_functions(lam)  # (C, Q, 10)
    return jnp.einsum("cq,cqa->ca", (weights * point_pressures).reshape(polygon.shape[0], num_points), shape)


def calc_surface_loads(problem: ElasticProblem, surface, vertices=None):
    """The consistent nodal loads (num_nodes, 3) of a contact surface's tractions on
    the elastomer: each polygon's pressure p along its normal (pure)."""
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    integrals = calc_polygon_node_integrals(vertices, problem.tets, surface)  # (C, 10)
    forces = integrals[:, :, None] * surface.normals_S[:, None, :]
    nodes = problem.tet_nodes[jnp.maximum(surface.tet_index, 0)]
    return jax.ops.segment_sum(forces.reshape(-1, 3), nodes.reshape(-1), num_segments=problem.num_nodes)


def calc_elastic_readings(fields: ReceptiveFields, surface) -> Float[Array, " num_barometers"]:
    """What each elastic barometer reads of a contact surface, Pa (pure; jittable,
    vmappable over surfaces, differentiable in the surface and the fields):
    sum over polygons and nodes of int p N_a dA (n . w_a)."""
    integrals = calc_polygon_node_integrals(fields.vertices, fields.tets, surface)  # (C, 10)
    nodes = fields.tet_nodes[jnp.maximum(surface.tet_index, 0)]  # (C, 10)
    along = jnp.einsum("cabk,ck->cab", fields.responses[nodes], surface.normals_S)  # (C, 10, B)
    return jnp.einsum("ca,cab->b", integrals, along)

