"""Taxels: ray-triangle intersection against hand-computed cases, culled vs brute-force
sampling, exactness under uniform pressure, convergence in the number of rays, and
gradients against finite differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import central_difference

from hydrotact._errors import HydrotactError
from hydrotact.contact import (
    Capacity,
    ContactSurface,
    HalfSpace,
    TetClusters,
    calc_contact_surface,
    calc_polygon_integrals,
    compute_contact_surface,
    make_cylinder_probe,
    make_pose,
    make_sphere_probe,
    make_tet_clusters,
)
from hydrotact.field import PressureField, make_laplace_problem, make_pressure_field, solve_strain
from hydrotact.sensors import load_sensor
from hydrotact.taxel import (
    TaxelCapacity,
    TaxelLayout,
    calc_spiral,
    calc_taxel_pressures,
    calc_taxel_rays,
    intersect_ray_triangle,
    make_taxel_layout,
    sample_taxels,
)
from hydrotact.taxel._patterns import calc_taxel_footprints

PAD_TOP = 4e-3
TRIANGLE = jnp.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 1.0]])
UP = jnp.array([0.0, 0.0, 1.0])


def _intersect(origin, direction=UP, triangle=TRIANGLE):
    hit, t, u, v = intersect_ray_triangle(jnp.asarray(origin, float), jnp.asarray(direction, float), *triangle)
    return bool(hit), float(t), float(u), float(v)


# --- ray against triangle ------------------------------------------------------------


def test_ray_hits_inside_with_hand_computed_distance_and_barycentrics():
    hit, t, u, v = _intersect([0.5, 0.25, -2.0])
    assert hit
    assert t == pytest.approx(3.0, abs=1e-15)
    assert (u, v) == pytest.approx((0.25, 0.125), abs=1e-15)  # p = u v1 + v v2 from v0 = 0


def test_oblique_ray_distance():
    direction = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
    hit, t, u, v = _intersect([0.0, 0.5, 0.0], direction)
    assert hit and t == pytest.approx(np.sqrt(2.0), abs=1e-14)
    assert (u, v) == pytest.approx((0.5, 0.25), abs=1e-14)


@pytest.mark.parametrize(
    "origin",
    [[1.5, 1.5, 0.0], [-0.1, 0.5, 0.0], [0.5, -0.1, 0.0], [3.0, 0.0, 0.0]],
    ids=["beyond the hypotenuse", "left of the y edge", "below the x edge", "beyond a corner"],
)
def test_ray_misses_outside(origin):
    hit, t, _, _ = _intersect(origin)
    assert not hit and t == np.inf


@pytest.mark.parametrize(
    "origin", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]], ids=["edge x", "edge y", "hypotenuse", "corner 0", "corner 1"]
)
def test_edges_and_corners_hit(origin):
    hit, t, _, _ = _intersect(origin)
    assert hit and t == pytest.approx(1.0)


def test_parallel_ray_misses_even_in_the_plane():
    assert not _intersect([0.5, 0.5, 1.0], [1.0, 0.0, 0.0])[0]
    assert not _intersect([0.5, 0.5, 0.0], [0.0, 1.0, 0.0])[0]


def test_back_face_hits_and_behind_the_origin_misses():
    reversed_triangle = TRIANGLE[jnp.array([0, 2, 1])]
    assert _intersect([0.5, 0.5, 0.0], UP, reversed_triangle)[0]  # two-sided
    assert _intersect([0.5, 0.5, 2.0], -UP)[0]  # from above, going down
    assert not _intersect([0.5, 0.5, 2.0], UP)[0]  # triangle behind the ray


def test_degenerate_triangle_misses_with_finite_gradient():
    flat = jnp.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0]])
    assert not _intersect([0.5, 0.0, 0.0], UP, flat)[0]

    def f(z):
        hit, t, u, v = intersect_ray_triangle(jnp.array([0.5, 0.0, z]), UP, *flat)
        return jnp.where(hit, t + u + v, 0.0)

    assert np.isfinite(float(jax.grad(f)(0.0)))


def test_shared_edge_is_watertight():
    """A ray exactly along the diagonal shared by two triangles hits one of them, for
    many positions along it (the plain test can miss both by round-off)."""
    square = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.0], [0.0, 1.0, 1.0]]) * 3.1e-4
    lower, upper = jnp.asarray(square[[0, 1, 2]]), jnp.asarray(square[[0, 2, 3]])
    for s in np.linspace(0.01, 0.99, 97) * 3.1e-4:
        origin = jnp.array([s, s, 0.0])
        assert bool(intersect_ray_triangle(origin, UP, *lower)[0]) or bool(intersect_ray_triangle(origin, UP, *upper)[0])


@pytest.mark.parametrize("is_cone", [False, True], ids=["disk", "cone"])
def test_footprints_shrunk_to_a_point_agree_with_moller_trumbore(is_cone, rng):
    """The footprint clip's inside test is the Moller-Trumbore test written as edge
    functions of the ray plane: a footprint 1e-7 of the triangles' size covers all of
    its square exactly where intersect_ray_triangle hits (away from the edges by more
    than the footprint), none where it misses, and sees the same distance along the
    ray and the same (barycentric, perspective-correct on a cone) pressure."""
    from hydrotact.taxel._footprint import calc_footprint_hits, calc_pair_geometry
    from hydrotact.taxel._patterns import calc_perpendicular_frame

    position = jnp.asarray(rng.normal(size=3) * 1e-3)
    axis = jnp.asarray(rng.normal(size=3))
    axis = axis / jnp.linalg.norm(axis)
    u, v = calc_perpendicular_frame(axis)
    frame = np.stack([np.asarray(u), np.asarray(v), np.asarray(axis)])  # rows: the taxel frame in S
    num_triangles, num_rays, size = 120, 150, 1e-3
    local = rng.uniform(-size, size, size=(num_triangles, 3, 3))
    local[..., 2] = rng.uniform(0.5 * size, 2 * size, size=(num_triangles, 3))
    corners_S = position[None, None] + np.einsum("tck,kl->tcl", local, frame)
    pressures = rng.uniform(1e3, 1e4, size=(num_triangles, 3))
    # Rays: points of the ray plane (disk: offsets in mm; cone: tangents of the angle).
    scale = 1.0 if is_cone else size
    xy = rng.uniform(-scale, scale, size=(num_rays, 2))
    pair = calc_pair_geometry(
        jnp.asarray(position)[:, None, None],
        u[:, None, None],
        v[:, None, None],
        axis[:, None, None],
        jnp.asarray(corners_S.transpose(1, 2, 0))[..., None],
        jnp.asarray(pressures.T)[..., None],
        jnp.asarray(is_cone),
        jnp.ones((num_triangles, 1), bool),
    )
    half = jnp.asarray(1e-7 * scale)
    area, integral, depth = (np.asarray(a) for a in calc_footprint_hits(pair, jnp.asarray(xy[:, 0])[None], jnp.asarray(xy[:, 1])[None], half, jnp.asarray(is_cone)))
    # The same rays, cast: from the apex along (X, Y, 1) on a cone, along the axis from (X, Y) on a disk.
    offsets = xy @ frame[:2]
    if is_cone:
        directions = offsets + frame[2][None]
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.broadcast_to(np.asarray(position), (num_rays, 3))
    else:
        directions = np.broadcast_to(frame[2], (num_rays, 3))
        origins = np.asarray(position)[None] + offsets
    columns = [jnp.asarray(c.T)[:, None, :] for c in (origins, directions)] + [jnp.asarray(corners_S[:, j].T)[..., None] for j in range(3)]
    hit, t, bu, bv = (np.asarray(a) for a in intersect_ray_triangle(*columns))
    weights = np.stack([1.0 - bu - bv, bu, bv])
    margin = weights.min(axis=0) / np.maximum(np.abs(weights).max(axis=0), 1.0)
    inside, outside = hit & (margin > 1e-4), margin < -1e-4
    assert inside.sum() > 500 and outside.sum() > 500, (inside.sum(), outside.sum())
    assert np.all(~hit[outside])
    np.testing.assert_allclose(area[inside], 1.0, rtol=1e-6)
    np.testing.assert_array_equal(area[outside], 0.0)
    np.testing.assert_allclose(depth[inside], t[inside], rtol=1e-6)
    expected = np.einsum("jtr,jt->tr", weights, pressures.T)
    np.testing.assert_allclose(integral[inside] / area[inside], expected[inside], rtol=1e-6)


# --- receptive fields ----------------------------------------------------------------


def test_ray_patterns_cover_the_field_evenly():
    fractions, azimuths = calc_spiral(200)
    assert np.all((fractions > 0) & (fractions < 1)) and np.all((azimuths >= 0) & (azimuths < 2 * np.pi))
    position, axis = jnp.array([1e-3, -2e-3, 0.5e-3]), jnp.array([0.0, 0.6, 0.8])
    origins, directions, weights = calc_taxel_rays(position, axis, 1.1e-3, False, 200)
    offsets = origins - position[None]
    np.testing.assert_allclose(offsets @ axis, 0.0, atol=1e-18)  # in the disk's plane
    assert np.max(np.linalg.norm(offsets, axis=1)) < 1.1e-3
    np.testing.assert_allclose(directions, np.broadcast_to(axis, directions.shape))
    # equal-area samples: the mean of |offset|^2 is r^2 / 2, as for a uniform disk
    assert np.mean(np.sum(np.asarray(offsets) ** 2, axis=1)) == pytest.approx(0.5 * 1.1e-3**2, rel=1e-3)
    origins, directions, weights = calc_taxel_rays(position, axis, np.radians(40.0), True, 200)
    angles = np.arccos(np.clip(np.asarray(directions) @ np.asarray(axis), -1, 1))
    assert np.all(angles < np.radians(40.0)) and np.all(np.asarray(weights) > 0)
    np.testing.assert_allclose(origins, np.broadcast_to(position, origins.shape))
    # equal solid angle: mean of cos(angle) is that of a uniform cap, (1 + cos a) / 2
    assert np.mean(np.cos(angles)) == pytest.approx(0.5 * (1 + np.cos(np.radians(40.0))), rel=1e-6)


@pytest.mark.parametrize("kind, size", [("disk", 1.1e-3), ("cone", np.radians(40.0))])
def test_footprint_weights_have_the_fields_moments(kind, size):
    """The footprints' kernel sum_i w_i box_i (a square's own X^2 moment is s^2 / 12)
    has the first and second moments of the field's weight (r - d)^2 (per solid angle
    on a cone, over the gnomonic plane): a quadratic pressure reads its exact mean."""
    is_cone = kind == "cone"
    centres, halves, weights = (np.asarray(a) for a in calc_taxel_footprints(jnp.asarray(size), jnp.asarray(is_cone), 64))
    d = np.linspace(0.0, size, 200001)[:-1] + 0.5 * size / 200000
    rho, measure = (np.tan(d), np.sin(d)) if is_cone else (d, d)
    target = 0.5 * np.sum((size - d) ** 2 * measure * rho**2) / np.sum((size - d) ** 2 * measure)
    x, y, own = centres[:, 0], centres[:, 1], (2.0 * halves) ** 2 / 12.0
    total = np.sum(weights)
    moments = [np.sum(weights * m) / total for m in (x, y, x * x + own, x * y, y * y + own)]
    np.testing.assert_allclose(moments, [0.0, 0.0, target, 0.0, target], rtol=1e-6, atol=1e-9 * target)


def test_bad_layouts_are_refused():
    with pytest.raises(HydrotactError, match="taxel 0: the axis is zero"):
        make_taxel_layout([[0, 0, 0]], [[0, 0, 0]], ["disk"], [1e-3])
    with pytest.raises(HydrotactError, match="half-angle"):
        make_taxel_layout([[0, 0, 0]], [[0, 0, 1]], ["cone"], [2.0])
    with pytest.raises(HydrotactError, match="'disk' or 'cone'"):
        make_taxel_layout([[0, 0, 0]], [[0, 0, 1]], ["ring"], [1e-3])
    with pytest.raises(HydrotactError, match="same number of taxels"):
        make_taxel_layout([[0, 0, 0]], [[0, 0, 1], [0, 0, 1]], ["disk"], [1e-3])


# --- sampling ------------------------------------------------------------------------


def make_plane_surface(height, pressure, half_size=8e-3, cells=5, capacity=40) -> ContactSurface:
    """A square of side 2 half_size at z = height, cut into cells x cells quadrilateral
    polygons (so rays meet shared edges), each at uniform `pressure`."""
    edges = np.linspace(-half_size, half_size, cells + 1)
    vertices = np.zeros((capacity, 8, 3))
    counts = np.zeros(capacity, dtype=np.int32)
    k = 0
    for i in range(cells):
        for j in range(cells):
            x0, x1, y0, y1 = edges[i], edges[i + 1], edges[j], edges[j + 1]
            # counter-clockwise about the normal -z
            vertices[k, :4] = [[x0, y0, height], [x0, y1, height], [x1, y1, height], [x1, y0, height]]
            counts[k] = 4
            k += 1
    pressures = np.where(np.arange(8)[None] < counts[:, None], pressure, 0.0)
    normal = jnp.array([0.0, 0.0, -1.0])
    integrals = jax.vmap(calc_polygon_integrals, in_axes=(0, 0, 0, None))(jnp.asarray(vertices), jnp.asarray(counts), jnp.asarray(pressures), normal)
    valid = counts >= 3
    return ContactSurface(
        vertices_S=jnp.asarray(vertices),
        pressures=jnp.asarray(pressures),
        counts=jnp.asarray(counts),
        normals_S=jnp.broadcast_to(normal, (capacity, 3)),
        valid=jnp.asarray(valid),
        areas=integrals[0],
        pressure_integrals=integrals[1],
        first_moments_S=integrals[2],
        pressure_moments_S=integrals[3],
        tet_index=jnp.where(jnp.asarray(valid), 0, -1),
        other_index=jnp.full(capacity, -1),
        did_overflow=jnp.asarray(False),
        needed=jnp.array([0, 0, 0, k]),
    )


def _mixed_layout():
    """Disks on the PCB and tilted cones, all looking up at the plane z = 4 mm."""
    positions = [[0.0, 0.0, 0.0], [2.2e-3, 0.0, 0.0], [-3e-3, 1e-3, 1e-3], [1e-3, 2e-3, 0.5e-3]]
    axes = [[0, 0, 1], [0, 0, 1], [0.3, 0.1, 1.0], [-0.5, 0.0, 1.0]]
    return make_taxel_layout(positions, axes, ["disk", "disk", "cone", "cone"], [1.1e-3, 0.7e-3, np.radians(40), np.radians(25)])


@pytest.mark.parametrize("num_rays", [1, 7, 64, 257])
def test_uniform_pressure_reads_exactly_that_pressure(num_rays):
    surface = make_plane_surface(PAD_TOP, 12345.0)
    readings, _ = sample_taxels(_mixed_layout(), surface, num_rays)
    np.testing.assert_allclose(readings.pressures, 12345.0, rtol=1e-13)
    np.testing.assert_allclose(readings.coverage, 1.0, rtol=1e-13)


class _Sensor(eqx.Module):
    """A built-in sensor's unit-modulus Laplace field, tet clusters and taxels (what
    hydrotact.sim's sensor model holds, built here from the stages the taxel tests need)."""

    field: PressureField
    clusters: TetClusters
    layout: TaxelLayout


def _make_sensor(name) -> _Sensor:
    spec = load_sensor(name)
    mesh = spec.make_mesh()
    strain = solve_strain(make_laplace_problem(mesh, source=spec.name)).strain
    layout = make_taxel_layout(spec.taxel_positions_S, spec.taxel_axes_S, spec.taxel_field_kinds, spec.taxel_field_sizes)
    return _Sensor(make_pressure_field(mesh, strain, 1.0), make_tet_clusters(mesh.vertices, mesh.tets), layout)


def _unit_readings(model: _Sensor, probe, X_SR, contact=Capacity(), taxel=TaxelCapacity(), num_rays=64):
    """Taxel readings per pascal of E at pose X_SR, and whether a buffer overflowed (pure)."""
    surface = calc_contact_surface(model.field, probe, X_SR, contact, model.clusters)
    readings = calc_taxel_pressures(model.layout, surface, num_rays, taxel)
    return readings.pressures, surface.did_overflow | readings.did_overflow


@pytest.fixture(scope="module")
def pad_model():
    return _make_sensor("pad5x5")


@pytest.fixture(scope="module")
def sphere_model():
    return _make_sensor("sphere8-cones")


def _pad_surface(model, probe, x, y, depth):
    surface, _ = compute_contact_surface(model.field, probe, make_pose([x, y, PAD_TOP - depth]), clusters=model.clusters)
    return surface


def test_culled_equals_brute_force_on_the_pad(pad_model):
    surface = _pad_surface(pad_model, make_cylinder_probe(2e-3), 1.3e-3, 0.4e-3, 0.45e-3)
    culled, capacity = sample_taxels(pad_model.layout, surface, 64)
    brute = jax.jit(lambda s: calc_taxel_pressures(pad_model.layout, s, 64, brute_force=True))(surface)
    assert np.count_nonzero(np.asarray(culled.pressures)) >= 2
    np.testing.assert_allclose(culled.pressures, brute.pressures, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(culled.coverage, brute.coverage, rtol=1e-12, atol=1e-15)


def test_culled_equals_brute_force_with_cones(sphere_model):
    surface, _ = compute_contact_surface(sphere_model.field, HalfSpace(), make_pose([0.0, 0.0, 14e-3]), clusters=sphere_model.clusters)
    culled, _ = sample_taxels(sphere_model.layout, surface, 32)
    brute = jax.jit(lambda s: calc_taxel_pressures(sphere_model.layout, s, 32, brute_force=True))(surface)
    assert np.count_nonzero(np.asarray(culled.pressures)) >= 3
    np.testing.assert_allclose(culled.pressures, brute.pressures, rtol=1e-12, atol=1e-18)


def test_overflow_is_flagged_and_grown_away(pad_model):
    surface = _pad_surface(pad_model, make_cylinder_probe(2e-3), 0.0, 0.0, 0.45e-3)
    # The jitted kernel that sample_taxels runs, not the eager one (op by op): the
    # grown run below starts from this very program.
    from hydrotact.taxel._sample import _readings

    small = _readings(pad_model.layout, surface, 16, TaxelCapacity(8))
    assert bool(small.did_overflow) and small.needed.shape == (2,) and int(small.needed[0]) > 8
    grown, capacity = sample_taxels(pad_model.layout, surface, 16, capacity=TaxelCapacity(8))
    reference, _ = sample_taxels(pad_model.layout, surface, 16, capacity=TaxelCapacity(1 << 16))
    assert not bool(grown.did_overflow) and capacity.pairs >= int(small.needed[0])
    # grown once to what the small run counted, then fitted to what the grown run needed
    assert capacity == TaxelCapacity(8).grown_to(small.needed).fitted_to(grown.needed)
    assert all(size >= need for size, need in zip(capacity.sizes, np.asarray(grown.needed).tolist()))
    np.testing.assert_allclose(grown.pressures, reference.pressures, rtol=1e-14)


def test_empty_contact_reads_zero_with_finite_gradients(pad_model):
    probe = make_sphere_probe(2e-3)

    def first_taxel(z):
        return _unit_readings(pad_model, probe, make_pose(jnp.array([0.0, 0.0, z])))[0][12]

    value_and_grad = jax.jit(jax.value_and_grad(first_taxel))  # one compilation, not op by op
    value, slope = value_and_grad(PAD_TOP + 1e-3)
    assert float(value) == 0.0 and float(slope) == 0.0
    assert np.isfinite(float(value_and_grad(PAD_TOP)[1]))  # grazing


def test_batched_sampling_matches_one_by_one(pad_model):
    probe = make_cylinder_probe(2e-3)
    poses = jax.vmap(make_pose)(jnp.array([[x, 0.0, PAD_TOP - 0.4e-3] for x in (-1e-3, 0.0, 1.7e-3)]))
    surfaces, capacity = compute_contact_surface(pad_model.field, probe, poses, clusters=pad_model.clusters)
    batched, _ = sample_taxels(pad_model.layout, surfaces, 32)
    for k in range(3):
        one = jax.tree_util.tree_map(lambda a, k=k: a[k], surfaces)
        single, _ = sample_taxels(pad_model.layout, one, 32)
        np.testing.assert_allclose(batched.pressures[k], single.pressures, rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("case", ["pad, 3 mm sphere", "pad, 6 mm sphere off-centre", "sphere8, half-space"])
def test_taxel_values_converge_in_the_number_of_rays(case, pad_model, sphere_model):
    """The value for a fixed contact changes by < 1% between N = 64 and N = 256 (for
    contacts whose pressure falls to zero at their rim; see the cylinder test)."""
    if case.startswith("sphere8"):
        model = sphere_model
        surface, _ = compute_contact_surface(model.field, HalfSpace(), make_pose([0.0, 0.0, 13.5e-3]), clusters=model.clusters)
    else:
        model = pad_model
        radius, x = (3e-3, 0.3e-3) if "3 mm" in case else (6e-3, 1.4e-3)
        surface = _pad_surface(model, make_sphere_probe(radius), x, 0.2e-3, 0.45e-3)
    coarse, _ = sample_taxels(model.layout, surface, 64)
    fine, _ = sample_taxels(model.layout, surface, 256)
    coarse, fine = np.asarray(coarse.pressures), np.asarray(fine.pressures)
    strong = fine > 0.2 * fine.max()  # taxels that see the contact well
    assert strong.sum() >= 1
    np.testing.assert_array_less(np.abs(coarse[strong] - fine[strong]) / fine[strong], 0.01)


def test_sharp_rim_converges_more_slowly_but_converges(pad_model):
    """A flat-ended cylinder's pressure jumps to zero at its rim, so point sampling of
    the receptive field converges like N^-3/4 rather than smoothly: the error (as a
    fraction of the peak, over positions where the rim crosses the field) must still
    fall by at least 2x per 4x rays."""
    probe = make_cylinder_probe(2e-3)
    xs = np.linspace(0.5e-3, 1.6e-3, 8)
    poses = jax.vmap(make_pose)(jnp.array([[x, 0.2e-3, PAD_TOP - 0.45e-3] for x in xs]))
    surfaces, _ = compute_contact_surface(pad_model.field, probe, poses, clusters=pad_model.clusters)
    centre = _centre_taxel(pad_model).layout  # the others are not read: 25 x fewer rays to cast

    def centre_taxel(num_rays):
        readings, _ = sample_taxels(centre, surfaces, num_rays)  # more rays, more pieces: the buffers grow
        return np.asarray(readings.pressures)[:, 0]

    values = {n: centre_taxel(n) for n in (64, 256, 2048)}
    peak = values[2048].max()
    errors = {n: np.max(np.abs(values[n] - values[2048])) / peak for n in (64, 256)}
    assert errors[256] < 0.5 * errors[64], errors
    assert errors[256] < 0.04, errors


# --- gradients -----------------------------------------------------------------------


def _centre_taxel(model: _Sensor) -> _Sensor:
    """The pad with its centre taxel (b22, index 12) alone."""
    return eqx.tree_at(lambda m: m.layout, model, jax.tree_util.tree_map(lambda a: a[12:13], model.layout))


def test_gradients_match_finite_differences(pad_model):
    """d(taxel value)/d(probe translation, rotation, E, taxel position) against central
    differences, on the pad pressed by a sphere (a smooth contact); the centre taxel
    alone (the one read)."""
    pad_model = _centre_taxel(pad_model)
    probe = make_sphere_probe(3e-3)
    base = np.array([0.7e-3, 0.3e-3, PAD_TOP - 0.5e-3])
    rotation = np.array([0.02, -0.01, 0.0])
    _, contact_capacity = compute_contact_surface(pad_model.field, probe, make_pose(base, rotation), clusters=pad_model.clusters)

    def reading(model, translation, rotation_vector, modulus, positions):
        model = eqx.tree_at(lambda m: m.layout.positions_S, model, positions)
        pressures, did_overflow = _unit_readings(model, probe, make_pose(translation, rotation_vector), contact_capacity, TaxelCapacity())
        return modulus * pressures[0], did_overflow

    jitted = eqx.filter_jit(reading)

    def f(*a):  # every argument as a JAX array: one compilation serves every evaluation
        return jitted(a[0], *(jnp.asarray(x, jnp.float64) for x in a[1:]))[0]

    grad = eqx.filter_jit(jax.grad(lambda *a: reading(*a)[0], argnums=(1, 2, 3, 4)))
    args = (pad_model, jnp.asarray(base), jnp.asarray(rotation), jnp.asarray(2e5), pad_model.layout.positions_S)
    value, overflow = jitted(*args)
    assert not bool(overflow) and float(value) > 1e3
    grads = grad(*args)
    for axis in range(3):
        direction = np.eye(3)[axis]
        fd = central_difference(lambda x: f(pad_model, x, *args[2:]), base, direction, 1e-8)
        assert float(grads[0][axis]) == pytest.approx(fd, rel=2e-4, abs=1e2), ("translation", axis)
        fd = central_difference(lambda w: f(pad_model, args[1], w, *args[3:]), rotation, direction, 1e-6)
        assert float(grads[1][axis]) == pytest.approx(fd, rel=2e-4, abs=1e0), ("rotation", axis)
    fd = central_difference(lambda e: f(pad_model, args[1], args[2], e, args[4]), 2e5, 1.0, 10.0)
    assert float(grads[2]) == pytest.approx(fd, rel=1e-8)
    direction = np.zeros((1, 3))
    direction[0, 0] = 1.0
    fd = central_difference(lambda p: f(*args[:4], p), np.asarray(pad_model.layout.positions_S), direction, 1e-8)
    assert abs(fd) > 1e3  # the taxel's position matters here: the check can fail
    assert float(grads[3][0, 0]) == pytest.approx(fd, rel=2e-4, abs=1e2)


def make_disc_surface(centre_x, height=PAD_TOP, radius=1e-3, sectors=32, slope=0.3):
    """A flat disc of pressure (a flat probe's face) at z = height centred at
    (centre_x, 0): `sectors` triangles about its centre, the pressure 1 + slope x / radius
    Pa at its corners (linear, so it is exact on every triangle), dropping to 0 beyond
    its rim."""
    angles = jnp.linspace(0.0, 2.0 * jnp.pi, sectors + 1)
    rim = jnp.stack([centre_x + radius * jnp.cos(angles), radius * jnp.sin(angles), jnp.full(sectors + 1, height)], axis=1)
    centre = jnp.stack([centre_x, 0.0, height])
    vertices = jnp.zeros((sectors, 8, 3))
    vertices = vertices.at[:, 0].set(centre).at[:, 1].set(rim[:-1]).at[:, 2].set(rim[1:])
    counts = jnp.full(sectors, 3, dtype=jnp.int32)
    pressures = jnp.where(jnp.arange(8)[None] < 3, 1.0 + slope * (vertices[..., 0] - centre_x) / radius, 0.0)
    zeros = jnp.zeros(sectors)
    return ContactSurface(
        vertices_S=vertices,
        pressures=pressures,
        counts=counts,
        normals_S=jnp.broadcast_to(jnp.array([0.0, 0.0, -1.0]), (sectors, 3)),
        valid=jnp.ones(sectors, dtype=bool),
        areas=zeros,
        pressure_integrals=zeros,
        first_moments_S=jnp.zeros((sectors, 3)),
        pressure_moments_S=jnp.zeros((sectors, 3)),
        tet_index=jnp.zeros(sectors, dtype=jnp.int32),
        other_index=jnp.full(sectors, -1),
        did_overflow=jnp.asarray(False),
        needed=jnp.array([0, 0, 0, sectors]),
    )


DISC_TAXEL = ([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], ["disk"], [1.1e-3])


def _disc_reading(layout, x, num_rays):
    """The taxel's reading with a 2 mm flat disc of pressure centred at (x, 0.2 mm)."""
    surface = make_disc_surface(x)
    surface = eqx.tree_at(lambda s: s.vertices_S, surface, surface.vertices_S + jnp.array([[[0.0, 0.2e-3, 0.0]]]))
    return calc_taxel_pressures(layout, surface, num_rays, TaxelCapacity(64)).pressures[0]


def sweep_disc_over_a_taxel(num_rays, step=0.0125e-3):
    """The reading of a 1.1 mm disk taxel at the origin as a 2 mm flat disc of pressure
    (a flat probe's face, 0.2 mm off the sweep line) slides along x from over the
    taxel to past its field."""
    layout = make_taxel_layout(*DISC_TAXEL)
    xs = jnp.arange(0.0, 2.3e-3, step)
    return np.asarray(jax.jit(jax.vmap(lambda x: _disc_reading(layout, x, num_rays)))(xs))


def test_compiled_and_eager_footprints_agree():
    """The disc's spokes are parallel to the footprints' sides up to round-off: the
    clip's huge intersection parameters for near-parallel edges once reached the
    moments, where the compiled code's fused multiply-adds turned their round-off into
    a wrong centroid (readings ~1% apart)."""
    layout = make_taxel_layout(*DISC_TAXEL)
    xs = jnp.asarray([0.75e-3, 1.4e-3])
    compiled = np.asarray(jax.jit(jax.vmap(lambda x: _disc_reading(layout, x, 64)))(xs))
    eager = np.array([float(_disc_reading(layout, x, 64)) for x in xs])
    np.testing.assert_allclose(compiled, eager, rtol=1e-12, atol=1e-12)


def test_flat_probe_rim_gives_a_smooth_curve_at_64_rays():
    """Issue 12: as a flat probe's rim (where the visible pressure drops to 0) crosses
    the rays, point samples gave a staircase (roughness 0.02-0.08, 64 rays 6% off the
    converged curve); footprints make the 64-ray curve smooth (roughness ~0.001) and,
    with deblurred, moment-matched weights, within 0.7% of the converged one (0.55%;
    0.76% deblurred only, 2% plain)."""
    coarse, fine = sweep_disc_over_a_taxel(64), sweep_disc_over_a_taxel(1024)
    peak = fine.max()
    roughness = np.max(np.abs(np.diff(coarse / coarse.max(), 2)))
    assert roughness < 0.005, roughness
    assert np.max(np.abs(coarse - fine)) < 0.007 * peak, np.max(np.abs(coarse - fine)) / peak
