"""Contact estimators (hydrotact.models): cells against a NumPy reference written
step by step, scan against the step loop, gradients against finite differences, the
published models' parameter counts, angle bins that cover the sensors' ranges."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from hydrotact.models import (
    PARAMETER_BUDGET,
    calc_bin_index,
    calc_estimator_sequence,
    calc_estimator_step,
    check_budget,
    count_macs,
    count_parameters,
    decode_bins,
    decode_estimator_outputs,
    init_estimator,
    make_angle_bins,
    make_estimator_spec,
)
from hydrotact.sensors import load_sensor


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def _numpy_sequence(spec, params, inputs):
    """The estimator written out in NumPy, one sample and one gate at a time."""
    p = jax.tree_util.tree_map(np.asarray, params)
    hidden = [np.zeros(h) for h in spec.hidden]
    outputs = []
    for x in np.asarray(inputs):
        h_in = x
        if spec.architecture == "mlp":
            for layer in p["layers"]:
                h_in = np.maximum(layer["w"] @ h_in + layer["b"], 0.0)
        else:
            for k, layer in enumerate(p["layers"]):
                h, size = hidden[k], spec.hidden[k]
                if spec.architecture == "rnn":
                    h_new = np.tanh(layer["w_ih"] @ h_in + layer["b_ih"] + layer["w_hh"] @ h + layer["b_hh"])
                else:
                    w_ir, w_iz, w_in = (layer["w_ih"][g * size : (g + 1) * size] for g in range(3))
                    w_hr, w_hz, w_hn = (layer["w_hh"][g * size : (g + 1) * size] for g in range(3))
                    b_ir, b_iz, b_in = (layer["b_ih"][g * size : (g + 1) * size] for g in range(3))
                    b_hr, b_hz, b_hn = (layer["b_hh"][g * size : (g + 1) * size] for g in range(3))
                    r = _sigmoid(w_ir @ h_in + b_ir + w_hr @ h + b_hr)
                    z = _sigmoid(w_iz @ h_in + b_iz + w_hz @ h + b_hz)
                    n = np.tanh(w_in @ h_in + b_in + r * (w_hn @ h + b_hn))
                    h_new = (1.0 - z) * n + z * h
                hidden[k] = h_new
                h_in = h_new
        outputs.append(p["head"]["w"] @ h_in + p["head"]["b"])
    return np.array(outputs)


@pytest.mark.parametrize("architecture", ["gru", "rnn", "mlp"])
@pytest.mark.parametrize("binned", [True, False])
def test_estimators_match_a_numpy_reference_and_their_step_loop(architecture, binned):
    spec = make_estimator_spec(load_sensor("sphere8"), architecture, binned)
    params = init_estimator(spec, jax.random.PRNGKey(3), jnp.float64)
    inputs = jax.random.normal(jax.random.PRNGKey(4), (40, spec.num_inputs), jnp.float64)
    _, scanned = jax.jit(lambda p, x: calc_estimator_sequence(spec, p, x))(params, inputs)
    np.testing.assert_allclose(scanned, _numpy_sequence(spec, params, inputs), rtol=1e-12, atol=1e-12)
    state, looped = None, []
    for x in inputs:  # one sample at a time, as the microcontroller runs it
        state = state if state is not None else tuple(jnp.zeros(h, jnp.float64) for h in spec.hidden) if spec.recurrent else ()
        state, out = calc_estimator_step(spec, params, state, x)
        looped.append(out)
    np.testing.assert_allclose(np.array(looped), scanned, rtol=1e-12, atol=1e-12)
    batch = jax.random.normal(jax.random.PRNGKey(5), (3, 12, spec.num_inputs), jnp.float64)
    _, batched = jax.vmap(lambda x: calc_estimator_sequence(spec, params, x))(batch)
    for b in range(3):
        np.testing.assert_allclose(batched[b], calc_estimator_sequence(spec, params, batch[b])[1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("architecture", ["gru", "rnn", "mlp"])
def test_gradients_match_finite_differences(architecture):
    spec = make_estimator_spec(load_sensor("ellipsoid8"), architecture, True, hidden=(5, 4) if architecture != "rnn" else (6,))
    params = init_estimator(spec, jax.random.PRNGKey(7), jnp.float64)
    inputs = jax.random.normal(jax.random.PRNGKey(8), (9, spec.num_inputs), jnp.float64)

    def loss(p, x):
        out = decode_estimator_outputs(spec, calc_estimator_sequence(spec, p, x)[1])
        return jnp.sum(out["force"] ** 2) + jnp.sum(jnp.sin(out["theta"]) + out["phi"] ** 2) + jnp.sum(out["contact_probability"])

    check_grads(loss, (params, inputs), order=1, modes=["rev"], atol=1e-6, rtol=1e-6, eps=1e-6)


def test_published_parameter_counts_with_the_papers_bins():
    """The barometric estimation paper's models, counted with its settings (bins by
    floor): 4205 / 3960 Binned RNN, 3127 RNN, 3905 / 3580 Binned MLP, 5555 MLP."""
    expected = {
        ("sphere8", "rnn", True): 4205, ("ellipsoid8", "rnn", True): 3960, ("sphere8", "rnn", False): 3127, ("ellipsoid8", "rnn", False): 3127,
        ("sphere8", "mlp", True): 3905, ("ellipsoid8", "mlp", True): 3580, ("sphere8", "mlp", False): 5555,
    }
    for (sensor, architecture, binned), count in expected.items():
        assert count_parameters(make_estimator_spec(load_sensor(sensor), architecture, binned, cover="floor")) == count
    spec = make_estimator_spec(load_sensor("sphere8"), "rnn", True)
    assert count_macs(spec) == 48 * (8 + 48) + 48 * 29  # matrix-vector MACs per step


def test_every_default_estimator_fits_the_budget_and_an_oversized_one_is_refused():
    for sensor in ("pad5x5", "sphere8", "ellipsoid8"):
        spec = load_sensor(sensor)
        for architecture in ("gru", "rnn", "mlp"):
            for binned in (True, False):
                assert check_budget(make_estimator_spec(spec, architecture, binned)) <= PARAMETER_BUDGET
        gru = make_estimator_spec(spec, "gru", True)
        bigger = make_estimator_spec(spec, "gru", True, hidden=(gru.hidden[0] + 1,) * 2)
        assert count_parameters(bigger) > PARAMETER_BUDGET  # the default is the largest that fits
        with pytest.raises(ValueError, match="over the budget"):
            check_budget(bigger)


def test_bins_cover_the_sensors_whole_angle_ranges():
    width = math.pi / 16
    for sensor, theta_count, phi_count in (("sphere8", 8, 16), ("ellipsoid8", 8, 13)):
        spec = load_sensor(sensor)
        for (low, high), count in ((spec.theta_range, theta_count), (spec.phi_range, phi_count)):
            bins = make_angle_bins(low, high)
            assert bins.count == count and bins.width == width
            angles = np.linspace(low, high, 1001)
            index = np.asarray(calc_bin_index(bins, jnp.asarray(angles)))
            edges = bins.start + index * width
            assert np.all((edges <= angles + 1e-12) & (angles <= edges + width + 1e-12))  # every angle inside its bin
            np.testing.assert_allclose(bins.centres.mean(), 0.5 * (low + high), atol=1e-12)  # centred
    floor = make_angle_bins(*load_sensor("ellipsoid8").phi_range, cover="floor")
    assert floor.count == 12 and floor.start + 12 * width < np.radians(72.0)  # the paper's: the top uncovered


def test_binned_angles_decode_as_the_weighted_mean_of_bin_centres():
    bins = make_angle_bins(-math.pi / 4, math.pi / 4)
    logits = jnp.asarray(np.random.default_rng(0).normal(size=(5, bins.count)))
    weights = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    np.testing.assert_allclose(decode_bins(bins, logits), weights @ bins.centres, rtol=1e-12)
    sharp = 50.0 * jax.nn.one_hot(3, bins.count)
    np.testing.assert_allclose(decode_bins(bins, sharp), bins.centres[3], atol=1e-12)
