"""The one forward model, sim.calc_simulation: gradients against central differences
(viscoelastic material and barometer signal), jit, vmap over trajectories and no
recompilation for a second trajectory of the same shape, and regression against logs
recorded with the code before the forward model was made one function."""

import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import count_compilations

from hydrotact.contact import make_cylinder_probe, make_sphere_probe
from hydrotact.data import make_material_document, material_prony
from hydrotact.sensors import load_sensor
from hydrotact.sim import BarometerSettings, calc_simulation, compute_unit_responses, make_sensor_model, make_trajectory, read_trajectory, simulate, simulate_log
from hydrotact.visco import make_barometer_signal, make_prony

DATA = Path(__file__).parent / "data"
PAD_TOP = 4e-3


@pytest.fixture(scope="module")
def pad_model():
    return make_sensor_model("pad5x5", num_rays=8)


def _press(top=PAD_TOP):
    """A probe pressed at an off-grid point, held, slid, released: 12 samples."""
    times = np.array([0.0, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0, 1.3, 1.6, 1.8, 1.9, 2.0])
    depth = np.array([0.0, 0.15, 0.3, 0.42, 0.42, 0.42, 0.44, 0.44, 0.44, 0.3, 0.1, 0.0]) * 1e-3
    x = 0.37e-3 + np.linspace(0.0, 0.2e-3, len(times))
    y = -0.23e-3 + np.zeros(len(times))
    return make_trajectory(times, np.column_stack([x, y, top - 0.05e-3 - depth]), np.column_stack([np.zeros(len(times)), 0.02 * np.ones(len(times)), np.zeros(len(times))]))


def _material():
    return make_prony(6e5, [2.5e5, 1.5e5], [0.3, 3.0])


def _barometer(model):
    spec = load_sensor("pad5x5")
    rng = np.random.default_rng(3)
    return make_barometer_signal(spec.part, model.num_taxels, gains=1.0 + 0.05 * rng.standard_normal(model.num_taxels), offsets=30.0 * rng.standard_normal(model.num_taxels), noise_rms=0.0)


# A sphere: its contact pressure falls to 0 at the contact's edge, so every reading is
# smooth in the parameters (a flat punch's edge is a jump that rays cross).
SPHERE = make_sphere_probe(3e-3)


@eqx.filter_jit
def _objective(model, material, trajectory, signal, capacity):
    """A scalar of the readings that every parameter reaches: a weighted sum over
    samples and channels, plus the vertical force (no noise key: deterministic)."""
    samples = calc_simulation(model, material, SPHERE, trajectory, capacity, barometer=signal)
    weights = jnp.linspace(0.5, 1.5, samples.readings.size).reshape(samples.readings.shape)
    return jnp.sum(weights * (samples.readings - signal.ambient)) + 1e3 * jnp.sum(samples.force_S[:, 2])


@pytest.fixture(scope="module")
def arguments(pad_model):
    # no quantisation: its straight-through gradient is not the derivative of the
    # rounded reading, which central differences would see
    signal = eqx.tree_at(lambda s: s.lsb, _barometer(pad_model), jnp.asarray(0.0))
    trajectory = _press()
    # buffers that hold every pose (grown until nothing overflows): a truncated buffer
    # would make the readings jump
    unit, capacity = compute_unit_responses(pad_model, SPHERE, trajectory.X_SR)
    assert not np.any(unit.did_overflow) and np.max(unit.taxel_pressures) > 0.0
    return (pad_model, _material(), trajectory, signal, capacity)


@pytest.fixture(scope="module")
def gradient(arguments):
    return eqx.filter_jit(eqx.filter_grad(lambda args: _objective(*args)))(arguments)


@pytest.mark.parametrize(
    "name, select, index, step",
    [
        ("taxel position x", lambda a: a[0].layout.positions_S, (12, 0), 1e-8),
        ("taxel position y", lambda a: a[0].layout.positions_S, (12, 1), 1e-8),
        ("taxel axis", lambda a: a[0].layout.axes_S, (12, 1), 1e-4),
        ("E_inf", lambda a: a[1].long_term_modulus, (), 1e3),
        ("E_1", lambda a: a[1].moduli, (0,), 1e3),
        ("E_2", lambda a: a[1].moduli, (1,), 1e3),
        ("tau_1", lambda a: a[1].taus, (0,), 1e-3),
        ("tau_2", lambda a: a[1].taus, (1,), 1e-2),
        ("channel gain", lambda a: a[3].gains, (12,), 1e-4),
        ("channel offset", lambda a: a[3].offsets, (12,), 1e-2),
        ("probe translation x", lambda a: a[2].translations, (5, 0), 1e-8),
        ("probe translation z", lambda a: a[2].translations, (5, 2), 1e-8),
    ],
)
def test_gradient_matches_central_differences(arguments, gradient, name, select, index, step):
    analytic = float(select(gradient)[index])

    def shifted(delta):
        return eqx.tree_at(select, arguments, select(arguments).at[index].add(delta))

    numeric = (float(_objective(*shifted(step))) - float(_objective(*shifted(-step)))) / (2 * step)
    assert np.isfinite(analytic) and analytic != 0.0, (name, analytic)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-5, err_msg=name)


def test_disk_taxel_moved_along_its_axis_reads_the_same(arguments, gradient):
    """A disk field's rays run along the axis: sliding the taxel along it changes no
    hit, so the reading's derivative is exactly 0, both ways."""
    select = lambda a: a[0].layout.positions_S
    assert float(select(gradient)[12, 2]) == 0.0
    lower, upper = (eqx.tree_at(select, arguments, select(arguments).at[12, 2].add(delta)) for delta in (-1e-5, 1e-5))
    assert float(_objective(*lower)) == pytest.approx(float(_objective(*upper)), rel=1e-12)


def test_jit_vmap_over_trajectories_and_no_recompile(pad_model):
    probe = make_cylinder_probe(2e-3)
    material = _material()
    signal = _barometer(pad_model)
    first, second = _press(), _press(PAD_TOP + 0.1e-3)
    # buffers that hold both trajectories' poses (the pure call flags, never grows them)
    both_poses = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), first.X_SR, second.X_SR)
    _, capacity = compute_unit_responses(pad_model, probe, both_poses, chunk=first.num_samples)  # the chunks simulate() compiles below

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def run(trajectory, key):
        return calc_simulation(pad_model, material, probe, trajectory, capacity, barometer=signal, key=key)

    one = run(first, jax.random.PRNGKey(0))
    two = run(second, jax.random.PRNGKey(1))  # same shapes: no second trace
    assert not bool(np.any(np.asarray(one.unit.did_overflow) | np.asarray(two.unit.did_overflow)))
    both = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), first, second)
    keys = jnp.stack([jax.random.PRNGKey(0), jax.random.PRNGKey(1)])
    batched = eqx.filter_jit(eqx.filter_vmap(lambda t, k: calc_simulation(pad_model, material, probe, t, capacity, barometer=signal, key=k)))(both, keys)
    for k, single in enumerate((one, two)):
        np.testing.assert_allclose(batched.readings[k], single.readings, rtol=0, atol=1e-9)
        np.testing.assert_allclose(batched.force_S[k], single.force_S, rtol=1e-12, atol=1e-15)
    # the host entry gives the same samples (chunks, distinct poses, no cache)
    host = simulate(pad_model, material, probe, first, barometer=signal, key=jax.random.PRNGKey(0), capacity=capacity, cache=False)
    np.testing.assert_allclose(host.readings, one.readings, rtol=0, atol=1e-9)
    np.testing.assert_allclose(host.taxel_pressures, one.taxel_pressures, rtol=1e-12, atol=1e-9)
    # pressing: the centre taxels read, the contact pushes, the force points down
    assert np.max(one.taxel_pressures) > 1e3 and np.all(one.taxel_pressures >= 0.0)
    assert np.min(one.force_S[:, 2]) < -0.1


def test_simulate_compiles_once_for_trajectories_of_many_lengths(pad_model):
    """simulate pads its blocks of distinct poses to powers of two and its material and
    barometer pass to a few lengths: after one trajectory, shorter ones of other
    lengths compile none of the contact, ray or sample kernels (a loop over presses of
    many lengths used to compile them per length, until XLA ran out of memory; these
    lengths' programs are compiled nowhere else in the suite, so the shared persistent
    cache cannot hide one), and each gives the samples of the same pass at its own
    length, barometer noise included."""
    from hydrotact.sim import compute_trajectory_responses
    from hydrotact.sim._host import _calc_samples, calc_block_size, calc_padded_length

    assert [calc_block_size(n) for n in (1, 16, 17, 100, 128, 5000)] == [16, 16, 32, 128, 128, 128]
    assert [calc_padded_length(n) for n in (1, 64, 65, 80, 81, 127, 129, 1000)] == [64, 64, 80, 80, 96, 128, 160, 1024]
    probe = make_cylinder_probe(2e-3)
    material = _material()
    signal = make_barometer_signal(load_sensor("pad5x5").part, pad_model.num_taxels, noise_rms=3.0)
    full, key = _press(), jax.random.PRNGKey(5)
    simulate(pad_model, material, probe, full, barometer=signal, key=key, cache=False)
    parts = [jax.tree_util.tree_map(lambda a, n=n: np.asarray(a)[:n], full) for n in (9, 10, 11)]
    with count_compilations() as compilations:
        padded = [simulate(pad_model, material, probe, part, barometer=signal, key=key, cache=False) for part in parts]
    # Per length only two small ops of the pose rows (Trajectory.rows: a conversion and
    # a concatenation, hundredths of a second); unpadded, the contact and ray kernels
    # and the sample pass compiled again at each length as well.
    assert len(compilations) <= 2 * len(parts), compilations
    for part, samples in zip(parts, padded):
        unit = jax.tree_util.tree_map(jnp.asarray, compute_trajectory_responses(pad_model, probe, part, cache=False))
        exact = _calc_samples(pad_model, material, part.times, unit, signal, key)  # at the trajectory's own length
        assert samples.readings.shape == (part.num_samples, pad_model.num_taxels) and samples.modulus.shape == ()
        for name in ("readings", "taxel_pressures", "force_S", "theta", "contact"):
            np.testing.assert_array_equal(getattr(samples, name), np.asarray(getattr(exact, name)), err_msg=name)
    assert np.ptp(padded[-1].readings[:, 12]) > 100.0  # the press reads, with noise


def _reference(name):
    with np.load(DATA / "regression_logs.npz") as saved:
        columns = {key.split("/", 1)[1]: saved[key] for key in saved.files if key.startswith(f"{name}/") and not key.endswith("/metadata")}
        metadata = json.loads(str(saved[f"{name}/metadata"]))
    return columns, metadata


def _assert_same_log(log, name):
    columns, metadata = _reference(name)
    assert list(log.columns) == list(columns)
    for column, values in columns.items():
        np.testing.assert_allclose(log.columns[column], values, rtol=1e-12, atol=1e-12, err_msg=f"{name}: {column}")
    assert json.loads(json.dumps(log.metadata, sort_keys=True)) == metadata


def _demo_truth():
    document = make_material_document(6.0e5, [2.5e5, 1.5e5], [0.3, 3.0], name="demo truth", description="x", provenance={"method": "simulation"})
    return material_prony(document)


def simulate_regression_log(name):
    """One of the two logs of `tests/data/regression_logs.npz`, simulated now
    (`tests/data/record_regression_logs.py` records them with this function)."""
    if name == "demo":
        from hydrotact.cli.demo import SMOKE_PRESSES, make_demo_trajectory

        waypoints = np.array([[float(f"{value:.9g}") for value in row] for row in make_demo_trajectory(SMOKE_PRESSES)])
        trajectory = make_trajectory(waypoints[:, 0], waypoints[:, 1:4])
        barometer = BarometerSettings(seed=1, noise_rms=0.5, gain_spread=0.05, offset_spread=30.0, force_noise=0.005)
        log, _ = simulate_log("pad5x5", "cylinder:d=2mm", trajectory, _demo_truth(), num_rays=16, barometer=barometer, cache=False)
        return log
    trajectory = read_trajectory(DATA / "sphere_traj.csv")
    log, _ = simulate_log("sphere8", make_sphere_probe(3e-3), trajectory, _demo_truth(), num_rays=24, cache=False)
    return log


def test_demo_log_is_unchanged():
    """The demo's (smoke) log: the columns recorded."""
    _assert_same_log(simulate_regression_log("demo"), "demo")


def test_sphere8_log_is_unchanged():
    """A tilted Ø6 mm sphere pressed off-axis into sphere8 and slid (elastomer
    pressures, viscoelastic): the columns recorded."""
    _assert_same_log(simulate_regression_log("sphere"), "sphere")
