"""The forward model: linearity in E, agreement with the contact stage, contact angles
and normal force against geometry, buffer growth, and jit/vmap."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hydrotact._errors import HydrotactError
from hydrotact.contact import HalfSpace, compute_contact_surface, make_cylinder_probe, make_sphere_probe
from hydrotact.sim import (
    SimCapacity,
    calc_contact_angles,
    calc_simulation,
    make_sensor_model,
    make_trajectory,
    simulate,
)
from hydrotact.taxel import TaxelCapacity
from hydrotact.visco import make_prony

PAD_TOP = 4e-3
SPHERE_CENTRE = np.array([0.0, 0.0, 5e-3])
SPHERE_RADIUS = 10e-3


@pytest.fixture(scope="module")
def pad_model():
    return make_sensor_model("pad5x5", num_rays=32)


@pytest.fixture(scope="module")
def sphere_model():
    return make_sensor_model("sphere8", num_rays=32)


def _pad_trajectory():
    x = np.array([-1e-3, 0.0, 0.6e-3, 2.2e-3])
    return make_trajectory(np.arange(4) * 0.01, np.column_stack([x, 0.3 * x, np.full(4, PAD_TOP - 0.45e-3)]))


def test_response_is_linear_in_modulus_and_matches_the_contact_stage(pad_model):
    probe = make_cylinder_probe(2e-3)
    trajectory = _pad_trajectory()
    soft = simulate(pad_model, make_prony(1e6), probe, trajectory)
    stiff = simulate(pad_model, make_prony(3e6), probe, trajectory)
    np.testing.assert_allclose(stiff.taxel_pressures, 3 * soft.taxel_pressures, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(stiff.force_S, 3 * soft.force_S, rtol=1e-12, atol=1e-15)
    field = eqx.tree_at(lambda f: f.modulus, pad_model.field, jnp.asarray(1e6))
    surfaces, _ = compute_contact_surface(field, probe, trajectory.X_SR)
    force, torque = surfaces.calc_wrench()
    np.testing.assert_allclose(soft.force_S, force, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(soft.torque_S, torque, rtol=1e-12, atol=1e-18)
    # pressing down: the force on the sensor points down, the normal force is positive
    assert np.all(soft.force_S[:, 2] < -0.1) and np.all(soft.normal_force > 0.1)
    np.testing.assert_allclose(soft.contact, np.linalg.norm(soft.force_S, axis=1) > 0.1)
    # the taxel under the probe reads most
    assert np.argmax(soft.taxel_pressures[1]) == 12 and np.argmax(soft.taxel_pressures[3]) == 13
    # no contact angles on a flat pad
    assert np.all(np.isnan(soft.theta)) and np.all(np.isnan(soft.phi))


def test_normal_force_of_a_flat_press_is_minus_fz(pad_model):
    trajectory = make_trajectory([0.0, 0.01], [[0.0, 0.0, PAD_TOP - 0.2e-3], [0.0, 0.0, PAD_TOP - 0.4e-3]])
    samples = simulate(pad_model, make_prony(2e5), HalfSpace(), trajectory)
    np.testing.assert_allclose(samples.normal_force, -samples.force_S[:, 2], rtol=1e-9)
    np.testing.assert_allclose(samples.force_S[:, :2], 0.0, atol=1e-9 * np.abs(samples.force_S[:, 2]).max())
    # a half-space covers every taxel's field: all 25 read, symmetric about x = y up to
    # the sampling error of the ray pattern (a spiral is not mirror-symmetric), the centre most
    readings = samples.taxel_pressures[1].reshape(5, 5)
    assert np.all(readings > 0) and np.argmax(readings) == 12
    np.testing.assert_allclose(readings, readings.T, rtol=1e-2)  # 32 rays


def test_contact_angles_follow_the_papers_convention():
    n = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, 1.0, 1.0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    theta, phi = calc_contact_angles(jnp.asarray(SPHERE_CENTRE + 3e-3 * n), jnp.asarray(SPHERE_CENTRE)[None])
    np.testing.assert_allclose(theta, np.arcsin(-n[:, 1]), atol=1e-15)
    np.testing.assert_allclose(phi, np.arctan2(n[:, 0], n[:, 2]), atol=1e-15)
    np.testing.assert_allclose(theta[:3], [0.0, 0.0, np.pi / 2], atol=1e-15)
    np.testing.assert_allclose(phi[:3], [0.0, np.pi / 2, 0.0], atol=1e-15)


@pytest.mark.parametrize("theta, phi", [(0.0, 0.0), (0.3, -0.5), (-0.6, 0.4)])
def test_radial_press_on_the_sphere_recovers_its_angles_and_normal(sphere_model, theta, phi):
    """A sphere probe pushed radially into sphere8 at (theta, phi): the simulated
    angles and inward normal point back along that radius."""
    n = np.array([np.cos(theta) * np.sin(phi), -np.sin(theta), np.cos(theta) * np.cos(phi)])
    probe_radius, depth = 3e-3, 0.8e-3
    tip = SPHERE_CENTRE + (SPHERE_RADIUS - depth) * n
    # the sphere probe's tip is at its frame's origin and its body along +z: turn +z onto n
    axis = np.cross([0.0, 0.0, 1.0], n)
    angle = np.arccos(np.clip(n[2], -1, 1))
    rotation = axis / np.linalg.norm(axis) * angle if np.linalg.norm(axis) > 0 else np.zeros(3)
    trajectory = make_trajectory([0.0], [tip], [rotation])
    samples = simulate(sphere_model, make_prony(5e6), make_sphere_probe(probe_radius), trajectory)
    assert samples.contact[0]
    assert samples.theta[0] == pytest.approx(theta, abs=0.03)
    assert samples.phi[0] == pytest.approx(phi, abs=0.03)
    inward = samples.unit.normal_S[0]
    assert float(np.dot(inward, -n)) > np.cos(np.radians(4.0))
    assert samples.normal_force[0] == pytest.approx(np.linalg.norm(samples.force_S[0]), rel=0.01)


def test_buffers_grow_until_nothing_overflows(pad_model):
    probe = make_cylinder_probe(2e-3)
    trajectory = _pad_trajectory()
    tiny = SimCapacity(16, 16, 32, 32, 16)
    grown = simulate(pad_model, make_prony(1e6), probe, trajectory, capacity=tiny)
    reference = simulate(pad_model, make_prony(1e6), probe, trajectory)
    np.testing.assert_allclose(grown.taxel_pressures, reference.taxel_pressures, rtol=1e-13, atol=1e-9)
    pure = eqx.filter_jit(calc_simulation)(pad_model, make_prony(1e6), probe, trajectory, tiny)
    assert bool(np.any(pure.unit.did_overflow))  # the pure call reports, never hides, overflow


def test_simulation_vmaps_over_trajectories(pad_model):
    probe = make_cylinder_probe(2e-3)
    first, second = _pad_trajectory(), make_trajectory(np.arange(4) * 0.01, np.column_stack([np.zeros(4), np.linspace(-2e-3, 2e-3, 4), np.full(4, PAD_TOP - 0.3e-3)]))
    _, contact = compute_contact_surface(pad_model.field, probe, jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), first.X_SR, second.X_SR))
    capacity = SimCapacity.of(contact, TaxelCapacity(1 << 13))
    both = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), first, second)
    batched = eqx.filter_jit(eqx.filter_vmap(calc_simulation, in_axes=(None, None, None, 0, None)))(pad_model, make_prony(1e6), probe, both, capacity)
    for k, trajectory in enumerate((first, second)):
        one = simulate(pad_model, make_prony(1e6), probe, trajectory)
        np.testing.assert_allclose(batched.taxel_pressures[k], one.taxel_pressures, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(batched.normal_force[k], one.normal_force, rtol=1e-12, atol=1e-15)


def test_bad_material_and_trajectory_are_refused():
    with pytest.raises(HydrotactError, match="positive pressure"):
        make_prony(-1.0)  # the material: an elastic one is a Prony series with no terms
    with pytest.raises(HydrotactError, match="row 3: time 0.01 s does not increase"):
        make_trajectory([0.0, 0.01, 0.01], np.zeros((3, 3)))
    with pytest.raises(HydrotactError, match="row 2: position is not a finite number"):
        make_trajectory([0.0, 0.01], [[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(HydrotactError, match="unknown field kind"):
        make_sensor_model("pad5x5", field_kind="elastic")


def test_a_renamed_sensor_or_moved_barometers_compile_nothing_again(pad_model):
    """The model a kernel takes holds no name, and its layout is data: the same
    geometry under another name or with its barometers elsewhere has the same pytree
    structure and shapes, so every jitted stage reuses its programs."""
    import dataclasses

    from hydrotact.sensors import load_sensor

    spec = load_sensor("pad5x5")
    moved = dataclasses.replace(spec, name="pad5x5_moved", taxel_positions_S=spec.taxel_positions_S + np.array([2e-4, 0.0, 0.0]))
    other = make_sensor_model(load_sensor(moved.to_json()), num_rays=pad_model.num_rays)
    assert jax.tree_util.tree_structure(other) == jax.tree_util.tree_structure(pad_model)
    assert [np.shape(a) for a in jax.tree_util.tree_leaves(other)] == [np.shape(a) for a in jax.tree_util.tree_leaves(pad_model)]
    assert not np.allclose(np.asarray(other.layout.positions_S), np.asarray(pad_model.layout.positions_S))
    traces = []

    @eqx.filter_jit
    def kernel(model):
        traces.append(model)  # runs once per trace
        return model.layout.positions_S.sum()

    assert float(kernel(pad_model)) != float(kernel(other))
    assert len(traces) == 1


def test_a_press_computes_on_the_start_rung_without_climbing(pad_model, monkeypatch):
    """The pad press needs more polygons than the ladder's bottom rung holds: a
    simulation starts one rung up, so its first chunk compiles once, not twice."""
    from hydrotact.sim import _host

    calls = []
    kernel = _host._chunk_response
    monkeypatch.setattr(_host, "_chunk_response", lambda *args: calls.append(args[-1].sizes) or kernel(*args))
    trajectory = _pad_trajectory()
    unit, capacity = _host.compute_unit_responses(pad_model, make_cylinder_probe(2e-3), trajectory.X_SR, chunk=_host.calc_block_size(4))
    assert calls == [_host.calc_start_capacity().sizes]
    assert np.asarray(unit.needed)[:, 3].max() > SimCapacity().polygons  # the bottom rung would have overflowed
    assert _host.calc_ladder_rung(capacity) == _host.calc_start_capacity()
