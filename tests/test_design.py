"""Layout design: the closest-point and feasibility geometry against independent
checks, the information's gradients against finite differences and its change of
variables against the determinant identity, the constraints after optimisation, the
refusal of an impossible request, and the `hydrotact design` command end to end."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_one_line_error, run_main

from hydrotact._errors import HydrotactError
from hydrotact.datasets import DatasetConfig
from hydrotact.design import (
    DesignObjective,
    NoiseModel,
    calc_closest_points,
    calc_design_score,
    calc_layout_information,
    calc_neighbour_errors,
    calc_neighbour_score,
    calc_neighbour_targets,
    calc_prior_precision,
    draw_design_contacts,
    make_feasible_region,
)
from hydrotact.sensors import load_sensor
from hydrotact.sensors._inside import calc_surface_distances
from hydrotact.sim import make_sensor_model
from hydrotact.taxel import TaxelCapacity

jax.config.update("jax_enable_x64", True)

# The smoke regime of the design: a coarse sphere (fewer contact polygons), 8 rays.
REGIME = DatasetConfig(probe="sphere:r=3mm,subdivisions=1")


@pytest.fixture(scope="module")
def sphere8():
    """sphere8's layout under the ray-cast cones: the design of ray taxels (the elastic
    barometers' design is tested in test_elastic, on a coarse pad)."""
    spec = load_sensor("sphere8-cones")
    return spec, spec.make_mesh(check=False)


def test_closest_points_agree_with_the_distance_kernel_and_lie_on_their_triangles():
    rng = np.random.default_rng(3)
    triangles = rng.normal(size=(40, 3, 3))
    points = 2.0 * rng.normal(size=(200, 3))
    closest, distances, index = calc_closest_points(points, triangles)
    np.testing.assert_allclose(distances, calc_surface_distances(points, triangles), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(closest - points, axis=1), distances, rtol=1e-12)
    # On its triangle: barycentric coordinates in [0, 1] that rebuild the point.
    a, b, c = (triangles[index, k] for k in range(3))
    for k in range(len(points)):
        w = np.linalg.lstsq(np.stack([b[k] - a[k], c[k] - a[k]], axis=1), closest[k] - a[k], rcond=None)[0]
        assert w.min() > -1e-9 and w.sum() < 1.0 + 1e-9
        np.testing.assert_allclose(a[k] + w[0] * (b[k] - a[k]) + w[1] * (c[k] - a[k]), closest[k], atol=1e-12)


def test_the_projection_makes_any_layout_feasible_and_an_impossible_count_is_refused(sphere8):
    _, mesh = sphere8
    region = make_feasible_region(mesh, "inside", margin=1e-3, spacing=3e-3, max_tilt_deg=70.0)
    rng = np.random.default_rng(0)
    positions = rng.uniform([-15e-3, -15e-3, -5e-3], [15e-3, 15e-3, 20e-3], size=(8, 3))  # most outside
    positions[1] = positions[0] + 1e-4  # two almost on top of each other
    axes = rng.normal(size=(8, 3))
    axes[2] = [0.0, 0.0, -1.0]  # straight into the board
    assert region.violations(positions, axes)
    projected, unit = region.project_positions(positions), region.project_axes(axes)
    assert region.violations(projected, unit) == []
    # The tilt bound is met exactly by the clipped axis; a feasible layout stays put.
    np.testing.assert_allclose(unit[2, 2], np.cos(np.radians(70.0)))
    np.testing.assert_array_equal(region.project_positions(projected), projected)
    # Random feasible layouts are feasible; the board placement puts ports on z = 0.
    assert region.violations(*region.random_layout(6, rng)) == []
    board = make_feasible_region(mesh, "board", margin=1e-3, spacing=3e-3, max_tilt_deg=70.0)
    ports, board_axes = board.random_layout(5, rng)
    np.testing.assert_allclose(ports[:, 2], mesh.vertices[:, 2].min())
    assert board.violations(ports, board_axes) == []
    with pytest.raises(HydrotactError, match=r"cannot place 60 barometers 5 mm apart inside the elastomer .* room for \d+ at most"):
        make_feasible_region(mesh, "inside", margin=1e-3, spacing=5e-3, max_tilt_deg=70.0).random_layout(60, rng)
    # On risers of at most 2 mm: the projection brings every port down into the 1-2 mm
    # slab (the margin keeps them 1 mm off the board), and one above it is named.
    risers = make_feasible_region(mesh, "inside", margin=1e-3, spacing=3e-3, max_tilt_deg=70.0, max_height=2e-3)
    low = risers.project_positions(positions)
    assert risers.violations(low, unit) == [] and np.all((low[:, 2] >= 1e-3 - 1e-12) & (low[:, 2] <= 2e-3))
    assert np.any(projected[:, 2] > 2e-3) and any("mm above the board, over the 2 mm allowed" in p for p in risers.violations(projected, unit))
    ports, riser_axes = risers.random_layout(8, rng)
    assert risers.violations(ports, riser_axes) == [] and np.all(ports[:, 2] <= 2e-3)
    with pytest.raises(HydrotactError, match=r"cannot place 30 barometers 3 mm apart inside the elastomer no higher than 2 mm above the board"):
        risers.random_layout(30, rng)
    with pytest.raises(HydrotactError, match=r"--max-height: must be a height above the board greater than the margin"):
        make_feasible_region(mesh, "inside", margin=1e-3, spacing=3e-3, max_tilt_deg=70.0, max_height=0.5e-3)
    from hydrotact.design import DesignConfig, design_layout

    with pytest.raises(HydrotactError, match=r"--max-height: must be a height above the board in m, got '2mm'"):
        DesignConfig(max_height="2mm")
    with pytest.raises(HydrotactError, match=r"--balance: must be a number of at least 1 \(1 sums the target's components' errors\), got 0.5"):
        DesignConfig(balance=0.5)
    # A baseline layout to compare must keep the design's constraints: refused before any work.

    with pytest.raises(HydrotactError, match=r"compare\['hand-made'\]: the layout breaks the design's constraints: barometer \d+"):
        design_layout(sphere8[0], config=DesignConfig(contacts=8, restarts=1, steps=1), compare={"hand-made": (positions, unit)})


def test_a_dense_sensors_random_starts_come_from_its_own_layout():
    """pad5x5's 25 ports at the default 2.5 mm spacing and 1 mm margin: random packing
    jams at ~18 (it refused the default design of the built-in sensor), so the random
    starts are the sensor's own layout with each port moved where the spacing allows:
    feasible, each different, and one port more is still refused."""
    from hydrotact.design import DesignConfig
    from hydrotact.design._design import _own_layout

    spec, config = load_sensor("pad5x5"), DesignConfig()
    region = make_feasible_region(spec.make_mesh(check=False), "board", config.margin, config.spacing, config.max_tilt_deg)
    rng = np.random.default_rng(0)
    with pytest.raises(HydrotactError, match=r"cannot place 25 barometers .* random packing found room for \d+ at most;"):
        region.random_layout(25, rng)
    own = _own_layout(region, spec)
    assert own is not None and own.shape == (25, 3)
    starts = [region.random_layout(25, rng, own) for _ in range(3)]
    for positions, axes in starts:
        assert region.violations(positions, axes) == []
        assert np.abs(positions - own).max() > config.spacing  # moved, not the own layout again
    assert not np.allclose(starts[0][0], starts[1][0])
    region.random_layout(9, rng, own)  # fewer fit by packing alone
    with pytest.raises(HydrotactError, match=r"cannot place 26 barometers .* the sensor's own layout holds 25"):
        region.random_layout(26, rng, own)


@pytest.fixture(scope="module")
def linearised(sphere8):
    spec, _ = sphere8
    model = make_sensor_model(spec, num_rays=8)
    contacts, area = draw_design_contacts(spec, model, REGIME, 1e7, 16, np.random.default_rng(1))
    noise = NoiseModel(jnp.asarray(0.03), jnp.asarray(0.016), jnp.asarray(20.0), jnp.asarray(0.05), jnp.asarray(23675.0))
    return model, contacts, noise, calc_prior_precision(area, contacts.forces)


def test_contacts_reach_their_forces_and_the_information_changes_variables_exactly(linearised):
    model, contacts, noise, prior = linearised
    forces = np.asarray(contacts.forces)
    assert np.all(forces > 0.0) and np.all(np.asarray(contacts.depths) > 0.0)
    # The force Jacobian's depth entry is the slope the secant search used: positive.
    assert np.all(np.asarray(contacts.force_jacobians)[:, 2] > 0.0)
    information = calc_layout_information(model.layout, contacts, noise, 8, TaxelCapacity(16384, 16384))
    assert not bool(np.any(information.did_overflow))
    # Without the prior, det I(u, v, F) = det I(u, v, d) / (dF/dd)^2 (A = dθ/dq has
    # det dF/dd): recompute I(u, v, d) by hand from the same readings' Jacobian.
    info = np.asarray(information.information)
    f_q = np.asarray(contacts.force_jacobians)
    a = np.zeros((len(f_q), 3, 3))
    a[:, 0, 0] = a[:, 1, 1] = 1.0
    a[:, 2] = f_q
    info_q = np.einsum("nki,nkl,nlj->nij", a, info, a)  # I_q = Aᵀ I_θ A
    seen = np.linalg.matrix_rank(info_q, tol=1e-6 * np.abs(info_q).max()) == 3
    assert seen.any()
    np.testing.assert_allclose(
        np.linalg.slogdet(info[seen])[1], np.linalg.slogdet(info_q[seen])[1] - 2.0 * np.log(f_q[seen, 2]), rtol=1e-9
    )


def test_a_press_that_does_not_touch_carries_no_information():
    """A drawn depth where the skin gives no force (its force's Jacobian is zero) adds
    nothing to the information, not NaN: the prior keeps its score finite."""
    from hydrotact.design._objective import calc_contact_information

    noise = NoiseModel(*(jnp.asarray(v) for v in (0.03, 0.016, 20.0, 0.05, 2e4)))
    information, readings = calc_contact_information(jnp.zeros(4), jnp.zeros((4, 3)), jnp.zeros(3), 1e7, noise)
    np.testing.assert_array_equal(np.asarray(information), 0.0)
    touching, _ = calc_contact_information(jnp.full(4, 1e-4), jnp.ones((4, 3)), jnp.array([0.0, 0.0, 1e4]), 1e7, noise)
    assert np.all(np.isfinite(np.asarray(touching))) and float(touching[0, 0]) > 0.0


def test_the_neighbour_estimator_meets_its_closed_forms(linearised):
    _, _, noise, _ = linearised
    rng = np.random.default_rng(3)
    points = rng.normal(size=(40, 3)) * 1e-3
    # Readings that say nothing (all equal, or all past the channel's limit): every other
    # contact weighs the same, so each estimate is the mean of the others.
    others = (points.sum(axis=0) - points) / (len(points) - 1)
    expected = np.sum((others - points) ** 2, axis=1)
    for readings in (np.full((40, 3), 500.0), np.asarray(noise.limit) + rng.uniform(1.0, 1e4, size=(40, 3))):
        np.testing.assert_allclose(np.asarray(calc_neighbour_errors(jnp.asarray(readings), jnp.asarray(points), noise)), expected, rtol=1e-12)
    # The score weighs the components' mean squared errors by a p-norm: p = 1 sums them
    # (minus the mean squared error, mm²), a large p tends to the worst component's.
    readings, stretched = jnp.full((40, 3), 500.0), points * np.array([1.0, 3.0, 0.5])
    missed = ((stretched.sum(axis=0) - stretched) / 39 - stretched) ** 2  # each estimate the mean of the other 39
    per_component = np.mean(missed, axis=0) * 1e6
    np.testing.assert_allclose(np.asarray(calc_neighbour_errors(readings, jnp.asarray(stretched), noise, per_component=True)).mean(axis=0) * 1e6, per_component, rtol=1e-12)
    for balance, expected_score in ((1.0, -per_component.sum()), (4.0, -np.sum(per_component**4) ** 0.25), (50.0, -per_component.max())):
        np.testing.assert_allclose(float(calc_neighbour_score(readings, jnp.asarray(stretched), noise, balance)), expected_score, rtol=1e-6 if balance == 50.0 else 1e-12)
    whole = np.mean(np.sum(missed, axis=1)) * 1e6
    np.testing.assert_allclose(float(calc_neighbour_score(readings, jnp.asarray(stretched), noise)), -whole, rtol=1e-12)
    # Readings that tell the contacts apart, evenly in the estimator's features
    # (asinh(y / s), s the noise at zero), on a line 0.05 mm apart: inside, the
    # neighbours weigh alike on both sides and the estimate is exact; at the ends they
    # lie on one side, a few spacings off.
    line = np.column_stack([np.linspace(0.0, 10e-3, 201), np.zeros(201), np.zeros(201)])
    scale = float(jnp.sqrt(noise.variances(0.0)))
    readings = jnp.asarray(scale * np.sinh(np.column_stack([0.7e3 * line[:, 0], 0.7e3 * (10e-3 - line[:, 0])])))
    errors = np.sqrt(np.asarray(calc_neighbour_errors(readings, jnp.asarray(line), noise)))
    assert np.max(errors[20:-20]) < 1e-9 and 0.05e-3 < np.max(errors) < 0.3e-3 and np.median(errors) < 1e-9
    # From a separate reference pool nothing is left out: a query reading as pool member 0
    # does, the other five reading alike far away, weighs its twin 1 and each of the
    # five (at the fifth-nearest distance, the width) exp(-1).
    pool = jnp.asarray(np.vstack([[10.0, 10.0], np.tile([1e4, 5e3], (5, 1))]))
    where = rng.normal(size=(6, 3)) * 1e-3
    query = where[0] + 1e-3
    estimate = (where[0] + np.exp(-1.0) * where[1:].sum(axis=0)) / (1.0 + 5.0 * np.exp(-1.0))
    error = calc_neighbour_errors(pool[:1], jnp.asarray(query[None]), noise, pool, jnp.asarray(where))
    np.testing.assert_allclose(float(error[0]), np.sum((estimate - query) ** 2), rtol=1e-9)
    # What is estimated: on a sensor with contact angles, (θ, φ) as arcs at the mean
    # radius (the top of a 10 mm dome about (0, 0, 5 mm) is θ = φ = 0; a point on +x at
    # the centre's height is φ = 90 deg; one on -y is θ = 90 deg); else the points.
    centre = np.array([0.0, 0.0, 5e-3])
    skin = centre + 10e-3 * np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    np.testing.assert_allclose(np.asarray(calc_neighbour_targets(skin, centre)), 10e-3 * np.array([[0.0, 0.0], [0.0, np.pi / 2], [np.pi / 2, 0.0]]), atol=1e-15)
    np.testing.assert_array_equal(np.asarray(calc_neighbour_targets(skin)), skin)


def test_the_objective_gradients_match_finite_differences(linearised):
    model, contacts, noise, prior = linearised
    contacts = jax.tree_util.tree_map(lambda a: a[:4] if np.ndim(a) else a, contacts)  # four contacts: one compilation, small
    capacity = TaxelCapacity(16384, 16384)

    def scores(positions, axes):
        layout = model.layout.__class__(positions, axes, model.layout.field_sizes, model.layout.is_cone)
        sampled = calc_layout_information(layout, contacts, noise, 8, capacity)
        scores = [calc_design_score(sampled.information, prior, DesignObjective(name)) for name in ("d", "a")]
        neighbours = [calc_neighbour_score(sampled.readings, contacts.points_S, noise, balance) for balance in (1.0, 4.0)]
        return jnp.stack([*scores, *neighbours])

    jacobian = jax.jit(jax.jacrev(scores, argnums=(0, 1)))
    value = jax.jit(scores)
    positions, axes = model.layout.positions_S, model.layout.axes_S
    j_positions, j_axes = (np.asarray(j) for j in jacobian(positions, axes))  # (3, taxels, 3) each
    assert np.any(j_positions != 0.0) and np.any(j_axes != 0.0)
    checked = 0
    for taxel, k in [(0, 2), (1, 0), (3, 1), (6, 2)]:
        for which, (array, gradient, h) in enumerate(((positions, j_positions, 1e-6), (axes, j_axes, 1e-5))):
            step = jnp.zeros_like(array).at[taxel, k].set(h)
            plus = value(positions + step, axes) if which == 0 else value(positions, axes + step)
            minus = value(positions - step, axes) if which == 0 else value(positions, axes - step)
            fd = np.asarray(plus - minus) / (2 * h)
            for objective in range(4):
                ad = float(gradient[objective, taxel, k])
                scale = max(abs(ad), 1e-3 * float(np.abs(gradient[objective]).max()))
                assert abs(fd[objective] - ad) <= 2e-3 * scale, (("d", "a", "k", "k balanced")[objective], taxel, k, fd[objective], ad)
                checked += abs(ad) > 0.0
    assert checked >= 12


def test_design_command_writes_a_feasible_sensor_that_beats_the_built_in_and_resumes(tmp_path, capsys, sphere8, monkeypatch):
    out = tmp_path / "designed" / "sphere8_layout.json"
    args = ["design", "--sensor", "sphere8-cones", "--probe", REGIME.probe, "--contacts", 8, "--rays", 8, "--restarts", 1, "--steps", 6, "--spacing", "2.5e-3"]
    result = run_main(capsys, *args, "-o", out, "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    document = json.loads((tmp_path / "designed" / "sphere8_layout_report.json").read_text())
    designed, builtin = document["scores"]["designed"], document["scores"]["built-in"]
    assert designed["score"] > builtin["score"]
    for name in ("layouts", "convergence", "error_map"):
        assert (tmp_path / "designed" / f"sphere8_layout_{name}.png").stat().st_size > 10_000
    assert report["barometers"] == 8
    # The written sensor is a sensor every command reads; its layout keeps the constraints
    # (checked by the mesh's own point location).
    spec = load_sensor(out)
    _, mesh = sphere8
    region = make_feasible_region(mesh, "inside", margin=1e-3, spacing=2.5e-3, max_tilt_deg=75.0)
    assert region.violations(spec.taxel_positions_S, spec.taxel_axes_S) == []
    assert not np.allclose(spec.taxel_positions_S, sphere8[0].taxel_positions_S)
    assert not (tmp_path / "designed" / "sphere8_layout.json.partial").exists()
    # Killed during the second start, then started again: the first start is read
    # back, not climbed again, and the layout is the uninterrupted run's.
    from hydrotact.design import _design

    climb, calls = _design._climb, []

    def killed(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return climb(*args, **kwargs)

    monkeypatch.setattr(_design, "_climb", killed)
    again = tmp_path / "again.json"
    assert run_main(capsys, *args, "-o", again, "--no-plots").returncode == 130
    assert (tmp_path / "again.json.partial" / "start-00.npz").is_file() and not again.exists()
    calls.clear()
    monkeypatch.setattr(_design, "_climb", lambda *a, **k: calls.append(1) or climb(*a, **k))
    assert run_main(capsys, *args, "-o", again, "--no-plots").returncode == 0
    assert len(calls) == 1
    np.testing.assert_array_equal(load_sensor(again).taxel_positions_S, spec.taxel_positions_S)
    # Impossible requests: one line each, nothing written.
    crowded = run_main(capsys, "design", "--sensor", "sphere8", "--barometers", 80, "--spacing", "5e-3", "-o", tmp_path / "crowded.json")
    assert_one_line_error(crowded, "cannot place 80 barometers", "room for")
    assert not (tmp_path / "crowded.json").exists()
    assert_one_line_error(run_main(capsys, "design", "--sensor", "sphere8", "--steps", -1, "-o", tmp_path / "x.json"), "--steps")
