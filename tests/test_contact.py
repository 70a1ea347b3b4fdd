"""Contact surfaces: closed forms, broad phase vs brute force, gradients, edge cases,
and the probes' spec strings."""

import functools
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from helpers import count_compilations, lowest_vertex

from hydrotact import HydrotactError
from hydrotact.contact import (
    AbstractProbe,
    Capacity,
    HalfSpace,
    calc_contact_surface,
    calc_half_space_surface,
    calc_soft_rigid_surface,
    calc_soft_soft_surface,
    clip_polygon,
    compute_contact_surface,
    make_box_probe,
    make_cylinder_probe,
    make_pose,
    make_rigid_surface,
    make_sphere_probe,
    make_tet_clusters,
    parse_length,
    parse_probe,
)
from hydrotact.field import calc_distance_field, make_laplace_problem, make_pressure_field, solve_strain
from hydrotact.mesh import FREE, make_ball, make_box, make_seed_mesh

E = 1e5

# The brute-force and tie checks call the kernels directly, not through the jitted
# compute_contact_surface: run eagerly, a first call dispatches every op of the clipping
# one by one (the tie test took 51 s so, 14.5 s jitted). The gradient checks stay eager:
# there reverse mode jitted compiled longer than it ran (62 s eager, 125 s jitted).
_soft_rigid = eqx.filter_jit(calc_soft_rigid_surface)
_half_space = eqx.filter_jit(calc_half_space_surface)
_soft_soft = eqx.filter_jit(calc_soft_soft_surface)


@eqx.filter_jit
def _batched(kernel, bodies, poses, **options):
    """kernel(*bodies, X, **options) for each pose X, in one jitted program."""
    return jax.jit(jax.vmap(lambda X: kernel(*bodies, X, **options)))(poses)


def _ball_field(radius, num_layers, modulus=E):
    """A soft ball with the field p = E (1 - r / R) set at its vertices."""
    mesh = make_ball(radius, num_layers)
    r = np.linalg.norm(np.asarray(mesh.vertices), axis=1)
    strain = np.where(mesh.vertices_tagged(FREE), 0.0, 1.0 - r / radius)  # exactly 0 on the skin
    return mesh, make_pressure_field(mesh, jnp.asarray(strain), modulus)


def _sphere_plane_force(radius, depth, modulus=E):
    """int over the disk cut at height h = R - d of E (1 - sqrt(rho^2 + h^2) / R)."""
    h = radius - depth
    a2 = radius**2 - h**2
    return modulus * (np.pi * a2 - 2 * np.pi / (3 * radius) * (radius**3 - h**3))


def test_soft_sphere_pressed_by_a_plane_matches_the_closed_form():
    radius, depth = 5e-3, 1.5e-3
    exact = _sphere_plane_force(radius, depth)
    errors = []
    for num_layers in (3, 6, 12):
        _, field = _ball_field(radius, num_layers)
        surface, _ = compute_contact_surface(field, HalfSpace(), make_pose([0.0, 0.0, radius - depth]))
        force = np.asarray(surface.calc_force())
        np.testing.assert_allclose(force[:2], 0.0, atol=1e-9 * exact)
        errors.append(abs(-force[2] - exact) / exact)
    assert errors[-1] < 0.01, errors
    assert errors[0] > errors[1] > errors[2], errors
    # The P1 interpolant of a smooth field and faceted skin: second order.
    assert np.log2(errors[0] / errors[1]) > 1.5 and np.log2(errors[1] / errors[2]) > 1.5, errors


def test_uniform_pressure_force_is_pressure_times_projected_area():
    """A slab with the Laplace field between z = 0 (e = 1) and z = h (e = 0) and
    insulated sides has p = E (1 - z / h): a plane at height z0 feels exactly
    E (1 - z0 / h) over the full footprint; a tilted plane too, projected."""
    size, height = 4e-3, 2e-3
    mesh = make_box((size, size, height), 0.5e-3, sides="insulated")
    strain = solve_strain(make_laplace_problem(mesh), rtol=1e-14).strain
    field = make_pressure_field(mesh, strain, E)
    z0 = 1.3e-3
    surface, _ = compute_contact_surface(field, HalfSpace(), make_pose([0.0, 0.0, z0]))
    np.testing.assert_allclose(float(surface.total_area), size * size, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(surface.calc_force()), [0, 0, -E * (1 - z0 / height) * size * size], rtol=1e-10, atol=1e-12)
    # A box probe larger than the pad, tilted about x: the pressure is linear in z,
    # so the force is the mean pressure (at the centre) times the footprint, along the plane normal.
    angle = 0.1
    probe = make_box_probe((10e-3, 10e-3, 3e-3))
    X_SR = make_pose([0.0, 0.0, z0], [angle, 0.0, 0.0])
    tilted, _ = compute_contact_surface(field, probe, X_SR, Capacity(tets=1152))  # what it needs: from the default it grew twice
    normal = -np.asarray(X_SR.rotation)[:, 2]
    expected = E * (1 - z0 / height) * size * size / np.cos(angle) * normal
    np.testing.assert_allclose(np.asarray(tilted.calc_force()), expected * np.cos(angle) / np.cos(angle), rtol=1e-9, atol=1e-9 * np.linalg.norm(expected))
    np.testing.assert_allclose(float(tilted.total_area), size * size / np.cos(angle), rtol=1e-9)


def _surface_key(surface):
    valid = np.asarray(surface.valid)
    order = np.lexsort((np.asarray(surface.other_index)[valid], np.asarray(surface.tet_index)[valid]))
    return (
        np.asarray(surface.tet_index)[valid][order],
        np.asarray(surface.other_index)[valid][order],
        np.asarray(surface.areas)[valid][order],
        np.asarray(surface.pressure_integrals)[valid][order],
    )


def _assert_same_surface(culled, brute):
    """The same polygons (same tet and triangle pairs) with the same values; XLA may
    fuse the two programs differently, so values agree to round-off."""
    assert not bool(culled.did_overflow)
    tets, others, areas, integrals = _surface_key(culled)
    ref_tets, ref_others, ref_areas, ref_integrals = _surface_key(brute)
    np.testing.assert_array_equal(tets, ref_tets)
    np.testing.assert_array_equal(others, ref_others)
    np.testing.assert_allclose(areas, ref_areas, rtol=1e-12)
    np.testing.assert_allclose(integrals, ref_integrals, rtol=1e-12)


def test_broad_phase_matches_brute_force_soft_rigid():
    field = make_pressure_field(mesh := make_seed_mesh("pad5x5", 1.1e-3), calc_distance_field(mesh), E)
    probe = make_cylinder_probe(2e-3, length=3e-3, num_sides=12)
    clusters = make_tet_clusters(field.vertices, field.tets, cluster_size=16)
    for xyz in ([0.3e-3, -0.2e-3, 3.6e-3], [6.3e-3, 0.0, 3.5e-3], [0.0, 0.0, 5e-3]):
        X = make_pose(xyz, [0.05, 0.1, 0.2])
        brute = _soft_rigid(field, probe, X, brute_force=True)
        _assert_same_surface(_soft_rigid(field, probe, X, Capacity(1024, 256, 8192)), brute)
        _assert_same_surface(_soft_rigid(field, probe, X, Capacity(1024, 256, 8192), clusters=clusters), brute)


def test_broad_phase_at_the_first_cluster_counts_its_tets_once():
    """A press near the corner where the Morton order starts meets cluster 0. The
    cluster search's empty slots point at cluster 0 too: their tets once counted as
    near, once per empty slot, so such a press needed more tets than the mesh has
    (the buffers grew until memory ran out) and, with room, duplicated cluster 0's
    polygons. Found by the dataset generator (tilted presses near sphere8's base)."""
    field = make_pressure_field(mesh := make_seed_mesh("pad5x5", 1.1e-3), calc_distance_field(mesh), E)
    probe = make_cylinder_probe(2e-3, length=3e-3, num_sides=12)
    clusters = make_tet_clusters(field.vertices, field.tets, cluster_size=16)
    X = make_pose([-6.2e-3, -6.2e-3, 0.3e-3])  # the cylinder cuts the pad's corner edge at its base
    first = np.asarray(field.vertices)[np.asarray(field.tets)[np.asarray(clusters.members)[0]]].reshape(-1, 3)
    assert np.all(first.min(axis=0) < np.array([-4.2e-3, -4.2e-3, 3.3e-3]))  # cluster 0 lies in the probe's box
    brute = _soft_rigid(field, probe, X, brute_force=True)
    assert float(brute.total_area) > 0.0
    culled = _soft_rigid(field, probe, X, Capacity(1024, 256, 8192), clusters=clusters)
    assert int(culled.needed[0]) < field.tets.shape[0]
    _assert_same_surface(culled, brute)


def test_broad_phase_matches_brute_force_half_space_and_soft_soft():
    mesh, field = _ball_field(5e-3, 2)
    X = make_pose([0.2e-3, 0.0, 3.9e-3], [0.2, 0.0, 0.0])
    brute = _half_space(field, X, brute_force=True)
    _assert_same_surface(_half_space(field, X), brute)
    clusters = make_tet_clusters(field.vertices, field.tets, cluster_size=16)
    _assert_same_surface(_half_space(field, X, Capacity(512, 0, 0, 1024), clusters=clusters), brute)
    X_SB = make_pose([1e-3, 0.5e-3, 9e-3], [0.3, 0.1, 0.0])
    culled = _soft_soft(field, field, X_SB, Capacity(512, 512, 0, 4096))
    brute = _soft_soft(field, field, X_SB, brute_force=True)
    _assert_same_surface(culled, brute)
    assert int(culled.num_polygons) > 10


def test_overflow_is_detected_and_retried():
    from hydrotact.contact._api import _single  # the jitted kernel the retry loop runs

    field = make_pressure_field(mesh := make_seed_mesh("pad5x5", 1.1e-3), calc_distance_field(mesh), E)
    clusters = make_tet_clusters(field.vertices, field.tets)
    probe = make_cylinder_probe(2e-3, num_sides=16)
    X = make_pose([0.0, 0.0, 3.5e-3])
    # Each buffer reports its own overflow, in the order the kernel fills them: the
    # tets near the probe, then the candidate pairs (boxes overlap) among the tets
    # that fitted, then the polygons (the pairs the plane tests keep) among the pairs
    # that fitted. Growing to what each overflow reports climbs through every buffer.
    # The steps here run the program the retry loop runs (the same kernel, clusters and
    # capacities), so the loop below compiles nothing new.
    capacity, overflowed = (first := Capacity(64, 64, 128, 128)), []
    while bool((step := _single(field, probe, X, capacity, clusters)).did_overflow):
        over = [k for k, (size, need) in enumerate(zip(capacity.sizes, np.asarray(step.needed).tolist())) if need > size]
        assert over, (capacity, step.needed)  # an overflow names the buffer it outgrew
        overflowed.append(over)
        capacity = capacity.grown_to(step.needed)
        assert all(capacity.sizes[k] >= int(step.needed[k]) for k in over)
    assert {k for over in overflowed for k in over} == {0, 2, 3} and len(overflowed) >= 3, overflowed  # tets, pairs, polygons
    with count_compilations() as compilations:
        surface, grown = compute_contact_surface(field, probe, X, first, clusters)
    assert not bool(surface.did_overflow) and grown.sizes == capacity.fitted_to(step.needed).sizes
    assert not compilations, compilations
    # The half-space's two buffers (tets by cluster, then polygons) grow as well.
    X_half = make_pose([0.0, 0.0, 3.5e-3])
    small = _single(field, HalfSpace(), X_half, Capacity(64, 0, 0, 64), clusters)
    assert bool(small.did_overflow) and int(small.needed[0]) > 64
    half_space, half_capacity = compute_contact_surface(field, HalfSpace(), X_half, Capacity(64, 0, 0, 64), clusters)
    assert not bool(half_space.did_overflow) and half_capacity.tets > 64 and half_capacity.polygons > 64
    assert int(half_space.num_polygons) == int(_half_space(field, X_half, brute_force=True).num_polygons)
    # Against buffers that hold the press from the start (no cluster search).
    reference = _soft_rigid(field, probe, X, Capacity(2048, 512, 16384, 4096))
    assert not bool(reference.did_overflow)
    np.testing.assert_allclose(np.asarray(surface.calc_force()), np.asarray(reference.calc_force()), rtol=1e-12, atol=1e-15)


def test_overflow_beyond_the_limit_is_a_clear_error(monkeypatch):
    from hydrotact import _buffers

    monkeypatch.setattr(_buffers, "MAX_BUFFER", 64)
    field = make_pressure_field(mesh := make_seed_mesh("pad5x5"), calc_distance_field(mesh), E)
    with pytest.raises(HydrotactError, match="the contact needs more than 64 entries in its \\w+ buffer .*overlap too deeply"):
        compute_contact_surface(field, make_cylinder_probe(2e-3), make_pose([0.0, 0.0, 3.5e-3]), Capacity(16, 16, 32))


def test_batched_trajectory_matches_single_poses():
    field = make_pressure_field(mesh := make_seed_mesh("pad5x5"), calc_distance_field(mesh), E)
    probe = make_cylinder_probe(2e-3)
    xs = np.linspace(-4.4e-3, 4.4e-3, 9)
    poses = jax.vmap(lambda x: make_pose(jnp.array([x, 0.0, 3.6e-3])))(jnp.asarray(xs))
    batch, capacity = compute_contact_surface(field, probe, poses, Capacity(polygons=1408))  # what it needs (one compilation)
    assert batch.calc_force().shape == (9, 3)
    for k in (0, 4, 8):
        single, _ = compute_contact_surface(field, probe, make_pose([xs[k], 0.0, 3.6e-3]), capacity)
        np.testing.assert_allclose(np.asarray(batch.calc_force()[k]), np.asarray(single.calc_force()), rtol=1e-12, atol=1e-15)


def test_the_column_clipping_is_the_single_polygon_clip_four_times(rng):
    """The soft-rigid kernel's clipping (P triangles by their tets' four faces, as
    arrays) against :func:`clip_polygon` applied face by face to one polygon at a time:
    random triangles about random tets, and dyadic ones that tie (a triangle in a face's
    plane, a corner on a tet vertex, an edge through a tet edge), where every distance
    is exact."""
    from hydrotact.contact._polygon import calc_tet_face_planes, clip_polygon, clip_polygon_by_tet_faces_columns

    unit = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    tets = [unit + rng.normal(scale=0.3, size=(4, 3)) for _ in range(200)]
    triangles = [rng.normal(scale=0.6, size=(3, 3)) + 0.25 for _ in range(200)]
    ties = [
        [[0.25, 0.25, 0.0], [0.5, 0.125, 0.0], [0.125, 0.5, 0.0]],  # in the face z = 0
        [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [-0.5, 0.5, 0.25]],  # a corner on vertex 0
        [[0.5, 0.0, -0.25], [0.5, 0.0, 0.75], [0.75, 0.5, 0.25]],  # an edge in the face y = 0
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],  # the face itself
        [[-0.5, -0.5, 0.5], [1.5, -0.5, 0.5], [0.5, 1.5, 0.5]],  # a cut through the middle, wider than the tet
    ]
    for triangle in ties:
        tets.append(unit.copy())
        triangles.append(np.asarray(triangle))
    for k in range(len(tets)):  # positively oriented, as the meshes are
        a, b, c, d = tets[k]
        if np.dot(np.cross(b - a, c - a), d - a) < 0:
            tets[k] = tets[k][[0, 2, 1, 3]]
    tets, triangles = jnp.asarray(np.stack(tets)), jnp.asarray(np.stack(triangles))
    planes = calc_tet_face_planes(tets)  # (P, 4, 4)
    normals, offsets = jnp.transpose(planes[..., :3], (1, 2, 0)), planes[..., 3].T
    columns, counts = jax.jit(clip_polygon_by_tet_faces_columns)(jnp.transpose(triangles, (2, 1, 0)), jnp.full(len(tets), 3), normals, offsets)

    @jax.jit
    @jax.vmap
    def one_by_one(triangle, tet_planes):
        vertices, count = jnp.zeros((8, 3)).at[:3].set(triangle), 3
        for face in range(4):
            vertices, count = clip_polygon(vertices, count, tet_planes[face, :3], tet_planes[face, 3])
        return vertices, count

    rows, row_counts = one_by_one(triangles, planes)
    np.testing.assert_array_equal(np.asarray(counts), np.asarray(row_counts))
    assert 0 < np.sum(np.asarray(counts) == 0) < len(tets) and np.all(np.asarray(counts)[-5:] >= 3)
    for k, count in enumerate(np.asarray(counts)):
        np.testing.assert_allclose(np.asarray(columns[:, :count, k]).T, np.asarray(rows[k, :count]), rtol=0, atol=1e-14, err_msg=str(k))


def test_clip_polygon_cases():
    square = jnp.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]] + [[0, 0, 0]] * 4, dtype=float)
    # Cut off the corner x + y > 1.5: a pentagon with area 1 - 0.125.
    out, count = clip_polygon(square, 4, jnp.array([1.0, 1.0, 0.0]), 1.5)
    assert int(count) == 5
    from hydrotact.contact import calc_polygon_integrals

    area, *_ = calc_polygon_integrals(out, count, jnp.zeros(8), jnp.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(float(area), 0.875, rtol=1e-14)
    # Entirely outside, entirely inside, and touching along an edge.
    assert int(clip_polygon(square, 4, jnp.array([1.0, 0.0, 0.0]), -1.0)[1]) == 0
    assert int(clip_polygon(square, 4, jnp.array([1.0, 0.0, 0.0]), 2.0)[1]) == 4
    edge, count = clip_polygon(square, 4, jnp.array([1.0, 0.0, 0.0]), 0.0)
    area, *_ = calc_polygon_integrals(edge, count, jnp.zeros(8), jnp.array([0.0, 0.0, 1.0]))
    assert float(area) == 0.0


def test_polygon_integrals_of_a_linear_pressure():
    from hydrotact.contact import calc_polygon_integrals

    # Unit right triangle in z = 0 with p = 1 + 2x + 3y: int p = 1/2 + 2/6 + 3/6 = 4/3.
    vertices = jnp.zeros((8, 3)).at[:3].set(jnp.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float))
    pressures = 1 + 2 * vertices[:, 0] + 3 * vertices[:, 1]
    area, integral, first, moment = calc_polygon_integrals(vertices, 3, pressures, jnp.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose([float(area), float(integral)], [0.5, 1 / 2 + 1 / 3 + 1 / 2], rtol=1e-14)
    np.testing.assert_allclose(np.asarray(first), [1 / 6, 1 / 6, 0], rtol=1e-14)
    # int x p = int x + 2 x^2 + 3 x y = 1/6 + 2/12 + 3/24.
    np.testing.assert_allclose(float(moment[0]), 1 / 6 + 1 / 6 + 1 / 8, rtol=1e-14)


@functools.cache
def _pad_setup():
    mesh = make_seed_mesh("pad5x5", 0.8e-3)
    return mesh, calc_distance_field(mesh)


def test_gradients_wrt_pose_modulus_and_field_soft_rigid(rng):
    mesh, strain = _pad_setup()
    probe = make_sphere_probe(1.5e-3, subdivisions=2)
    capacity = Capacity(2048, 512, 16384, 4096)

    def summary(translation, rotation_vector, modulus, strain):
        field = make_pressure_field(mesh, strain, modulus)
        surface = calc_soft_rigid_surface(field, probe, make_pose(translation, rotation_vector), capacity)
        force, torque = surface.calc_wrench(jnp.array([0.0, 0.0, 4e-3]))
        pressures = jnp.where(surface.valid[:, None] & (jnp.arange(8)[None] < surface.counts[:, None]), surface.pressures, 0.0)
        return jnp.concatenate([force, 1e3 * torque, jnp.array([jnp.sum(pressures) * 1e-8, surface.total_area * 1e6])])

    t0 = jnp.array([0.31e-3, -0.17e-3, 4e-3 - 0.6e-3])
    w0 = jnp.array([0.2, -0.1, 0.3])
    args = (t0, w0, jnp.asarray(E), jnp.asarray(strain))
    assert not bool(calc_soft_rigid_surface(make_pressure_field(mesh, strain, E), probe, make_pose(t0, w0), capacity).did_overflow)
    _check_jacobians(summary, args, steps=(1e-8, 1e-5, 1.0, 1e-5), rng=rng, skin=mesh.vertices_tagged(FREE))


def test_gradients_half_space_and_soft_soft(rng):
    mesh, field = _ball_field(5e-3, 3)
    strain = field.strain

    def half_space(translation, rotation_vector, modulus, strain):
        surface = calc_half_space_surface(make_pressure_field(mesh, strain, modulus), make_pose(translation, rotation_vector))
        force, torque = surface.calc_wrench()
        return jnp.concatenate([force, 1e3 * torque, jnp.array([surface.total_area * 1e6])])

    _check_jacobians(half_space, (jnp.array([0.1e-3, 0.2e-3, 3.7e-3]), jnp.array([0.1, 0.05, 0.0]), jnp.asarray(E), strain), (1e-8, 1e-5, 1.0, 1e-5), rng, mesh.vertices_tagged(FREE))

    capacity = Capacity(1024, 1024, 0, 4096)

    def soft_soft(translation, rotation_vector, modulus, strain):
        field_a = make_pressure_field(mesh, strain, modulus)
        surface = calc_soft_soft_surface(field_a, field, make_pose(translation, rotation_vector), capacity)
        force, torque = surface.calc_wrench()
        return jnp.concatenate([force, 1e3 * torque, jnp.array([surface.total_area * 1e6])])

    t0, w0 = jnp.array([0.7e-3, 0.3e-3, 9.1e-3]), jnp.array([0.2, -0.1, 0.05])
    assert not bool(calc_soft_soft_surface(field, field, make_pose(t0, w0), capacity).did_overflow)
    _check_jacobians(soft_soft, (t0, w0, jnp.asarray(E), strain), (1e-8, 1e-5, 1.0, 1e-5), rng, mesh.vertices_tagged(FREE))


def _check_jacobians(fn, args, steps, rng, skin=None):
    """Reverse-mode directional derivatives against central differences, per argument.

    Field values (argument 3) are perturbed only inside the body: on the skin the
    pressure is zero by definition, and where two skins meet (the rim of a soft-soft
    contact) both zero-pressure planes pass through the polygon corners, a genuine kink.
    """
    # One compiled program for the values and one for the derivative serve every
    # argument (the direction is an input, zero but for the argument checked); eagerly,
    # each call traced and compiled the kernels' loops again.
    def along(t, directions):
        return fn(*(arg + t * direction for arg, direction in zip(args, directions)))

    forward, derivative = jax.jit(along), jax.jit(jax.jacrev(along))
    zeros = [jnp.zeros_like(jnp.asarray(arg)) for arg in args]
    out = np.asarray(forward(0.0, zeros))
    for k, (arg, step) in enumerate(zip(args, steps)):
        direction = jnp.asarray(rng.normal(size=np.shape(arg)))
        if np.ndim(arg) == 0:
            direction = jnp.asarray(1.0)
        if k == 3 and skin is not None:
            direction = jnp.where(jnp.asarray(skin), 0.0, direction)
        directions = [direction if j == k else zero for j, zero in enumerate(zeros)]
        jacobian = derivative(0.0, directions)
        fd = (np.asarray(forward(step, directions)) - np.asarray(forward(-step, directions))) / (2 * step)
        scale = np.max(np.abs(fd)) + 1e-300
        assert np.all(np.isfinite(np.asarray(jacobian)))
        np.testing.assert_allclose(np.asarray(jacobian), fd, rtol=2e-4, atol=2e-4 * scale, err_msg=f"argument {k}; value {out}")


def test_edge_cases_give_finite_values_and_gradients():
    mesh = make_box((4e-3, 4e-3, 2e-3), 0.5e-3)
    field = make_pressure_field(mesh, calc_distance_field(mesh), E)
    probe = make_box_probe((2e-3, 2e-3, 1e-3))

    def force(z, rotation=(0.0, 0.0, 0.0)):
        return jnp.sum(calc_soft_rigid_surface(field, probe, make_pose(jnp.array([0.25e-3, 0.25e-3, z]), jnp.asarray(rotation))).calc_force())

    def half_force(z):
        return jnp.sum(calc_half_space_surface(field, make_pose(jnp.array([0.0, 0.0, z]))).calc_force())

    cases = {
        "empty (above the pad)": 3e-3,
        "grazing (touching the skin)": 2e-3,
        "coplanar with a layer of tet faces": 1.5e-3,
    }
    # Compiled once per function (the depth traced): eagerly, each call traced and
    # compiled the kernels' loops again.
    with_gradient = {fn: jax.jit(jax.value_and_grad(fn)) for fn in (force, half_force)}
    values = {}
    for label, z in cases.items():
        for fn in (force, half_force):
            value, gradient = with_gradient[fn](jnp.asarray(z))
            values[fn, z] = float(value)
            assert np.isfinite(float(value)) and np.isfinite(float(gradient)), (label, value, gradient)
    assert values[force, 3e-3] == 0.0 and values[half_force, 3e-3] == 0.0
    assert abs(values[force, 2e-3]) < 1e-12  # on the skin the pressure is 0 (up to rounding)
    # Zero rotation vector and an edge-on probe face stay finite too.
    value, gradient = jax.jit(jax.value_and_grad(lambda w: force(1.8e-3, w)))(jnp.zeros(3))
    assert np.isfinite(float(value)) and np.all(np.isfinite(np.asarray(gradient)))


def test_calc_contact_surface_dispatch_and_bad_other():
    mesh, field = _ball_field(5e-3, 2)
    with pytest.raises(HydrotactError, match="cannot compute contact with a str"):
        calc_contact_surface(field, "plane", make_pose())


# --- probes --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "probe",
    [
        HalfSpace(),
        make_cylinder_probe(2e-3),
        make_cylinder_probe(2e-3, length=3e-3, num_sides=12),
        make_cylinder_probe(0.0017),
        make_sphere_probe(3e-3),
        make_sphere_probe(2.5e-6, subdivisions=1),
        make_box_probe((4e-3, 4e-3, 2e-3)),
    ],
    ids=lambda probe: probe.spec,
)
def test_probe_spec_round_trips(probe):
    assert isinstance(probe, AbstractProbe) and probe.spec
    again = parse_probe(probe.spec)
    assert type(again) is type(probe) and again.spec == probe.spec
    assert eqx.tree_equal(again, probe)


def test_probe_specs_read_lengths_in_any_unit():
    assert make_cylinder_probe(2e-3).spec == "cylinder:d=2mm"
    assert HalfSpace().spec == "plane"
    for spec in ("cylinder:d=2mm", "cylinder:d=2000um", "cylinder:d=0.002", "cylinder:d=0.2cm", "cylinder:d=2e-3m"):
        assert eqx.tree_equal(parse_probe(spec), make_cylinder_probe(2e-3)), spec
    assert eqx.tree_equal(parse_probe("cylinder:d=2mm,length=10mm"), make_cylinder_probe(2e-3, 10e-3))
    assert eqx.tree_equal(parse_probe("sphere:r=3mm"), make_sphere_probe(3e-3))
    assert parse_length("2mm", "x") == 2e-3 and parse_length(" 0.5 um", "x") == 0.5e-6 and parse_length("3e-3", "x") == 3e-3


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("cone:h=1", "--probe: unknown probe 'cone:h=1'"),
        ("cylinder:r=2mm", "--probe: unknown probe 'cylinder:r=2mm'"),
        ("sphere:r=3mm,d=1mm", "--probe: unknown probe 'sphere:r=3mm,d=1mm'"),
        ("plane:d=1mm", "--probe: unknown probe 'plane:d=1mm'"),
        ("box:x=1mm,y=1mm", "--probe: unknown probe 'box:x=1mm,y=1mm'"),
        ("cylinder:d=2 furlongs", "--probe d: cannot read '2 furlongs' as a length"),
        ("cylinder:d=2mm,sides=many", "--probe sides: cannot read 'many' as a whole number"),
    ],
)
def test_bad_probe_specs_are_clear_errors(spec, message):
    with pytest.raises(HydrotactError, match=re.escape(message)):
        parse_probe(spec)


def test_contact_query_delegates_to_the_probe():
    mesh, field = _ball_field(5e-3, 2)
    X = make_pose([0.0, 0.0, 4.5e-3])
    probe = make_sphere_probe(3e-3)
    # compiled (eagerly, each call traced and compiled the kernels' loops again)
    by_query = jax.jit(lambda X: calc_contact_surface(field, probe, X, Capacity(512, 512, 8192, 2048)))(X)
    by_probe = jax.jit(lambda X: probe.calc_contact_surface(field, X, Capacity(512, 512, 8192, 2048)))(X)
    assert eqx.tree_equal(by_query, by_probe) and int(by_query.num_polygons) > 0
    half = jax.jit(lambda X: calc_contact_surface(field, HalfSpace(), X))(X)
    assert eqx.tree_equal(half, jax.jit(lambda X: calc_half_space_surface(field, X))(X))


# --- Ties: probe faces on layers of tet faces, planes on layers of vertices ----------

PAD_TOP = 4e-3
PAD_LAYERS = np.arange(1, 8) * 0.5e-3  # pad5x5's inner vertex layers, as depths below the top


def _tie_probes():
    """(label, probe, rotation vector, capacity) for the tie sweeps: the half-space, the
    upright and tilted 2 mm cylinder, a box whose bottom and side faces lie on the pad's
    vertex planes (x and y every 0.55 mm) when centred, and a box pressed edge first.

    The capacities hold each sweep (measured): from the default ones the sweep grew
    its buffers three or four times, each a compilation of 10-25 s, which the overflow
    tests already cover. Were the mesh to change, a sweep would grow them again."""
    tilt = np.array([np.deg2rad(15.0), np.deg2rad(10.0), 0.0])
    return [
        ("half-space", HalfSpace(), np.zeros(3), Capacity(7680, 8, 8, 7168)),
        ("upright cylinder", make_cylinder_probe(2e-3), np.zeros(3), Capacity(384, 256, 9216, 4096)),
        ("tilted cylinder", make_cylinder_probe(2e-3), tilt, Capacity(640, 256, 7680, 2816)),
        ("box on the vertex planes", make_box_probe((2.2e-3, 2.2e-3, 2e-3)), np.zeros(3), Capacity(896, 40, 6144, 2560)),
        ("edge-first box", make_box_probe((3e-3, 3e-3, 2e-3)), np.array([np.pi / 4, 0.0, 0.0]), Capacity(1024, 32, 4096, 1024)),
    ]


def _poses_at_depths(probe, rotation_vector, depths, xy=(0.0, 0.0)):
    """Poses that put the probe's lowest point `depths` below the pad's top."""
    heights = PAD_TOP - np.asarray(depths) - lowest_vertex(probe, rotation_vector)[2]
    translations = np.column_stack([np.full_like(heights, xy[0]), np.full_like(heights, xy[1]), heights])
    return jax.vmap(make_pose)(jnp.asarray(translations), jnp.asarray(np.broadcast_to(rotation_vector, translations.shape)))


@pytest.fixture(scope="module")
def pad_field():
    mesh = make_seed_mesh("pad5x5")
    field = make_pressure_field(mesh, calc_distance_field(mesh), E)
    return mesh, field, make_tet_clusters(field.vertices, field.tets)


@pytest.mark.parametrize("case", range(4), ids=[label for label, *_ in _tie_probes()[:4]])
def test_contact_is_continuous_through_every_vertex_layer(pad_field, case):
    """Depth sweeps through each inner vertex layer of pad5x5 (every 0.5 mm): the
    force and area change across the layer by no more than in the steps beside it;
    where a probe face lies exactly on a layer of tet faces (the half-space, the
    upright cylinder's tip, the box's bottom and sides), the value there is the mean of
    the poses 1 nm to either side, to 1e-6 (before the tie rule: twice that), and the
    poses 1-1024 ulps and 1e-13-1e-12 m to either side give it too (issue 48)."""
    _, field, clusters = pad_field
    label, probe, rotation, capacity = _tie_probes()[case]
    # Rigid meshes follow Drake's 5 pi / 8 rule, which drops the tip's polygons past
    # the pressure ridge at the pad's mid-plane (2 mm): their sweeps stop above it.
    layers = PAD_LAYERS if isinstance(probe, HalfSpace) else PAD_LAYERS[PAD_LAYERS < 2e-3]
    step = 2e-6
    offsets = np.array([-2 * step, -step, -1e-9, 0.0, 1e-9, step, 2 * step])
    depths = (layers[:, None] + offsets[None]).reshape(-1)
    poses = _poses_at_depths(probe, rotation, depths)
    # The same batch walks the probe's height through each layer in ulps (the pose a
    # depth written as 4 mm - 0.5 mm gives) and picometres.
    at_layer = np.asarray(poses.translation)[3 :: len(offsets)]
    ulps = np.array([-1024, -16, -2, -1, 1, 2, 16, 1024])
    heights = [[h + k * np.spacing(h[2]) * np.array([0.0, 0.0, 1.0]) for k in ulps] + [h + np.array([0.0, 0.0, d]) for d in (-1e-12, -1e-13, 1e-13, 1e-12)] for h in at_layer]
    heights = np.asarray(heights).reshape(-1, 3)
    rotations = np.broadcast_to(np.asarray(rotation, dtype=np.float64), heights.shape)
    poses = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), poses, jax.vmap(make_pose)(jnp.asarray(heights), jnp.asarray(rotations)))
    surfaces, _ = compute_contact_surface(field, probe, poses, capacity, clusters)
    force = np.asarray(jax.vmap(lambda s: s.calc_force())(surfaces))
    near = slice(len(depths), None)
    near_force, near_area = -force[near, 2].reshape(len(layers), -1), np.asarray(surfaces.total_area)[near].reshape(len(layers), -1)
    force = force[: len(depths)]
    normal_force = -force[:, 2].reshape(len(layers), -1)
    area = np.asarray(surfaces.total_area)[: len(depths)].reshape(len(layers), -1)
    # A hair to either side of a layer the probe's face lies on, the patch is kept once:
    # within 1e-6 of the tie's own value (before the one tie rule on both sides, a face
    # a few ulps on the rigid side lost the patch on the layer: half the area, no force).
    for name, values, near_values in (("force", normal_force, near_force), ("area", area, near_area)):
        np.testing.assert_allclose(near_values, np.broadcast_to(values[:, 3:4], near_values.shape), rtol=1e-6, err_msg=f"{label}: {name} a hair off the layers")
    assert np.all(normal_force > 0), (label, normal_force)
    for name, values in (("force", normal_force), ("area", area)):
        change = np.abs(np.diff(values[:, [0, 1, 3, 5, 6]], axis=1))  # steps of 2 um; the layer between steps 1 and 2
        beside = np.maximum(change[:, 0], change[:, 3])
        across = np.maximum(change[:, 1], change[:, 2])
        allowed = 1.5 * beside + 1e-9 * np.abs(values).max(axis=1)
        assert np.all(across <= allowed), f"{label}: {name} jumps at layers {layers[across > allowed] * 1e3} mm: {across} vs {beside}"
        if label in ("half-space", "upright cylinder", "box on the vertex planes"):
            np.testing.assert_allclose(values[:, 3], 0.5 * (values[:, 2] + values[:, 4]), rtol=1e-6, err_msg=f"{label}: {name} on the layers")


def test_ties_match_brute_force():
    """At poses exactly on vertex and face layers, the culled query (clusters included)
    gives the same polygons as slicing or clipping every tet."""
    mesh = make_seed_mesh("pad5x5", 1e-3)  # vertex layers every 1 mm, 4,704 tets
    field = make_pressure_field(mesh, calc_distance_field(mesh), E)
    clusters = make_tet_clusters(field.vertices, field.tets, cluster_size=16)
    depths = [1e-3, 2e-3, 2.47e-3, 3e-3]
    poses = _poses_at_depths(HalfSpace(), np.zeros(3), depths)
    brute = _batched(calc_half_space_surface, (field,), poses, brute_force=True)
    culled = _batched(calc_half_space_surface, (field,), poses, capacity=Capacity(4096, 0, 0, 4096), clusters=clusters)
    probes = [
        (make_box_probe((2e-3, 2e-3, 2e-3)), np.zeros(3)),
        (make_box_probe((3e-3, 3e-3, 2e-3)), np.array([np.pi / 4, 0.0, 0.0])),
    ]  # tilted cylinders against brute force: test_broad_phase_matches_brute_force_soft_rigid
    pairs = [(culled, brute)]
    for probe, rotation in probes:
        poses = _poses_at_depths(probe, rotation, depths[:2])
        brute = _batched(calc_soft_rigid_surface, (field, probe), poses, brute_force=True)
        culled = _batched(calc_soft_rigid_surface, (field, probe), poses, capacity=Capacity(1024, 256, 16384, 4096), clusters=clusters)
        pairs.append((culled, brute))
    for culled, brute in pairs:
        for k in range(culled.counts.shape[0]):
            one = jax.tree.map(lambda a, k=k: a[k], (culled, brute))
            _assert_same_surface(*one)
            assert int(one[1].num_polygons) > 0


def test_gradients_at_and_beside_ties(pad_field):
    """The derivative of the normal force in the depth is finite on a tie and 1 nm to
    either side of it, equals one of the one-sided derivatives on the half-space's tie
    (zero-area sections count), and equals central differences away from the layers."""
    _, field, clusters = pad_field
    for label, probe, rotation, capacity in (_tie_probes()[0], _tie_probes()[3]):
        depths = [1e-3 - 1e-9, 1e-3, 1e-3 + 1e-9, 0.73e-3, 0.73e-3 - 1e-8, 0.73e-3 + 1e-8]
        poses = _poses_at_depths(probe, rotation, depths)
        _, capacity = compute_contact_surface(field, probe, poses, capacity, clusters)

        def normal_force(X, probe=probe, capacity=capacity):
            return -calc_contact_surface(field, probe, X, capacity, clusters).calc_force()[2]

        # d/d(depth) = -d/dz of the pose's translation
        def deeper(X):
            return eqx.tree_at(lambda p: p.translation, jax.tree.map(jnp.zeros_like, X), jnp.array([0.0, 0.0, -1.0]))

        values, tangents = jax.jit(jax.vmap(lambda X: jax.jvp(normal_force, (X,), (deeper(X),))))(poses)
        values, tangents = np.asarray(values), np.asarray(tangents)
        assert np.all(np.isfinite(tangents)) and np.all(tangents > 0), (label, tangents)
        # On the layer the force has a kink (the field's gradient jumps there). For the
        # half-space the derivative is one of the one-sided ones (the poses 1 nm off
        # give them); where the box's sides lie on vertical vertex planes as well,
        # slivers whose edges lie in clipping planes leave it finite, within 15 %.
        beside = np.abs(tangents[[0, 2]] - tangents[1]) / tangents[1]
        assert beside.min() < (1e-5 if isinstance(probe, HalfSpace) else 0.15), (label, tangents[:3])
        np.testing.assert_allclose(tangents[3], (values[5] - values[4]) / 2e-8, rtol=1e-6, err_msg=f"{label} off the layers")


def _one_piece_cylinder(diameter, length, num_sides=48):
    """The cylinder of make_cylinder_probe as it was built before its wall was cut
    into rings: each side a single quad, two triangles the probe's whole length."""
    radius = diameter / 2
    angles = np.linspace(0.0, 2 * np.pi, num_sides, endpoint=False)
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    vertices = np.concatenate([np.column_stack([ring, np.zeros(num_sides)]), np.column_stack([ring, np.full(num_sides, length)]), [[0, 0, 0], [0, 0, length]]])
    i = np.arange(num_sides)
    j = (i + 1) % num_sides
    n = num_sides
    faces = np.concatenate([np.column_stack([np.full(n, 2 * n), j, i]), np.column_stack([np.full(n, 2 * n + 1), n + i, n + j]), np.column_stack([i, j, n + j]), np.column_stack([i, n + j, n + i])])
    return make_rigid_surface((vertices, faces))


def _one_piece_box(size):
    surface = trimesh.creation.box(extents=size)
    surface.apply_translation([0.0, 0.0, size[2] / 2])
    return make_rigid_surface(surface)


TILTED = (0.26113296, 0.17353392, -0.02284617)  # 15 degrees about x, then 10 about y


def _pressed_poses(probe, rotation_vectors, top=4e-3, depth=0.4e-3):
    """Poses with each rotation, the probe's lowest point `depth` below `top`, at two places."""
    translations, rotations = [], []
    for rotation_vector in rotation_vectors:
        turned = np.asarray(probe.vertices_R) @ np.asarray(make_pose((0, 0, 0), rotation_vector).rotation).T
        for x in (-1.3e-3, 0.7e-3):
            translations.append([x, 0.4 * x, top - depth - turned[:, 2].min()])
            rotations.append(rotation_vector)
    return jax.vmap(make_pose)(jnp.asarray(translations), jnp.asarray(rotations))


@pytest.mark.parametrize(
    "probe, one_piece, rotation_vectors",
    [
        (make_cylinder_probe(2e-3), _one_piece_cylinder(2e-3, 10e-3), [(0.0, 0.0, 0.0), TILTED]),
        (make_box_probe((4e-3, 4e-3, 2e-3)), _one_piece_box((4e-3, 4e-3, 2e-3)), [(0.0, 0.0, 0.0), (np.pi / 4, 0.0, 0.0)]),
    ],
    ids=["cylinder", "box"],
)
def test_probes_cut_into_pieces_press_like_one_piece_faces(probe, one_piece, rotation_vectors):
    mesh, strain = _pad_setup()
    field = make_pressure_field(mesh, strain, E)
    clusters = make_tet_clusters(mesh.vertices, mesh.tets)
    X_SR = _pressed_poses(probe, rotation_vectors)
    totals = []
    for rigid in (probe, one_piece):  # a capacity that fits both: one compilation each
        surface, _ = compute_contact_surface(field, rigid, X_SR, Capacity(512, 256, 8192, 1024), clusters)
        force, torque = jax.vmap(lambda s: s.calc_wrench())(surface)
        totals.append((np.asarray(force), np.asarray(torque), np.asarray(surface.total_area), np.asarray(surface.needed)))
    (force, torque, area, _), (force_one, torque_one, area_one, _) = totals
    assert np.all(np.abs(force[:, 2]) > 1e-3)  # every pose presses
    np.testing.assert_allclose(force, force_one, rtol=1e-11, atol=1e-13 * np.abs(force).max())
    np.testing.assert_allclose(torque, torque_one, rtol=1e-11, atol=1e-13 * np.abs(torque).max())
    np.testing.assert_allclose(area, area_one, rtol=1e-11)
    # Turned, the pieces keep the buffers near those of the upright probe (rows: two
    # upright poses, two turned); the one-piece faces' long boxes do not.
    upright, turned = np.max(totals[0][3][:2], axis=0), np.max(totals[0][3][2:], axis=0)
    assert np.all(turned <= 1.5 * upright + 16), (upright, turned)
    if probe.spec.startswith("cylinder"):
        assert np.max(totals[1][3][2:, 2]) > 2 * turned[2]  # the pairs the long wall triangles needed
