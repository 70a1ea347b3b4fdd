"""Estimator training pieces: the loss terms against direct NumPy sums, the arc length
against the paper's Eq. 2, sequences with burn-in against the paper's windows."""

import jax.numpy as jnp
import numpy as np

from hydrotact.models import (
    Normaliser,
    calc_arc_length,
    calc_loss_terms,
    calc_table_metrics,
    make_estimator_spec,
    make_sequences,
)
from hydrotact.sensors import load_sensor


def _targets(rng, n):
    contact = (rng.random(n) < 0.6).astype(float)
    theta = np.where(contact > 0, rng.uniform(-0.7, 0.7, n), np.nan)
    phi = np.where(contact > 0, rng.uniform(-2.2, 0.7, n), np.nan)
    return {"force": rng.normal(size=(n, 4)), "theta": theta, "phi": phi, "contact": contact, "mask": (rng.random(n) < 0.8).astype(float)}


def test_loss_terms_equal_direct_sums():
    rng = np.random.default_rng(0)
    for binned in (True, False):
        spec = make_estimator_spec(load_sensor("sphere8"), "gru", binned)
        raw = rng.normal(size=(200, spec.num_outputs))
        t = _targets(rng, 200)
        terms = calc_loss_terms(spec, jnp.asarray(raw), {k: jnp.asarray(v) for k, v in t.items()})
        m = t["mask"] > 0
        np.testing.assert_allclose(terms["force"], np.mean(np.mean((raw[:, :4] - t["force"]) ** 2, axis=1)[m]), rtol=1e-12)
        p = 1 / (1 + np.exp(-raw[:, spec.outputs["contact"].start]))
        bce = -(t["contact"] * np.log(p) + (1 - t["contact"]) * np.log(1 - p))
        np.testing.assert_allclose(terms["contact"], bce[m].mean(), rtol=1e-10)
        touching = m & (t["contact"] > 0)
        if binned:
            ce = 0.0
            for name, bins in (("theta", spec.theta_bins), ("phi", spec.phi_bins)):
                logits = raw[:, spec.outputs[name]]
                log_p = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
                k = np.clip(np.floor((np.nan_to_num(t[name]) - bins.start) / bins.width), 0, bins.count - 1).astype(int)
                ce = ce - log_p[np.arange(200), k]
            np.testing.assert_allclose(terms["angle"], ce[touching].mean(), rtol=1e-10)
        else:
            err = (raw[:, 4] - np.nan_to_num(t["theta"])) ** 2 + (raw[:, 5] - np.nan_to_num(t["phi"])) ** 2
            np.testing.assert_allclose(terms["angle"], err[touching].mean(), rtol=1e-12)


def test_arc_length_is_eq_2_with_latitude_and_longitude():
    rng = np.random.default_rng(1)
    t1, t2 = rng.uniform(-0.7, 0.7, (2, 100))
    p1, p2 = rng.uniform(-2.3, 0.7, (2, 100))
    eq2 = 0.01 * np.arccos(np.clip(np.sin(t1) * np.sin(t2) + np.cos(t1) * np.cos(t2) * np.cos(p1 - p2), -1, 1))  # θ the latitude
    np.testing.assert_allclose(calc_arc_length(t1, p1, t2, p2, 0.01), eq2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(calc_arc_length(t1, p1, t1, p1, 0.01), 0.0, atol=2e-9)


def test_table_metrics_of_a_perfect_estimate():
    rng = np.random.default_rng(2)
    spec = make_estimator_spec(load_sensor("sphere8"), "rnn", False)
    t = _targets(rng, 50)
    raw = np.zeros((50, spec.num_outputs))
    raw[:, :4] = t["force"]
    raw[:, 4], raw[:, 5] = np.nan_to_num(t["theta"]), np.nan_to_num(t["phi"])
    raw[:, 6] = np.where(t["contact"] > 0, 40.0, -40.0)
    metrics = calc_table_metrics(spec, jnp.asarray(raw), {k: jnp.asarray(v) for k, v in t.items()}, radius=0.01)
    for name, value in metrics.items():
        assert float(value) < 1e-8, name


def test_sequences_with_burn_in_cover_each_label_once_and_windows_match_the_paper():
    rng = np.random.default_rng(3)
    n = 230
    arrays = {"time": np.arange(n) / 100, "contact": (rng.random(n) < 0.5).astype(np.int8), "block_starts": np.array([0, 97])}
    for name in ("b0", "b1", "fx", "fy", "fz", "fn", "theta", "phi"):
        arrays[name] = rng.normal(size=n)
    norm = Normaliser.fit(np.column_stack([arrays["b0"], arrays["b1"]]))
    inputs, targets = make_sequences(arrays, ["b0", "b1"], norm, length=20, burn_in=8, dtype=np.float64)
    labelled = targets["force"][targets["mask"] > 0][:, 0]
    np.testing.assert_array_equal(np.sort(labelled), np.sort(arrays["fx"]))  # every label exactly once
    assert inputs.shape[1] == 28
    # No context crosses a block edge: the second block's first sequence starts with its own first sample.
    second = np.flatnonzero(np.isclose(targets["force"][:, 8, 0], arrays["fx"][97]))[0]
    np.testing.assert_allclose(inputs[second, :9], np.repeat(norm(np.column_stack([arrays["b0"], arrays["b1"]]))[97:98], 9, axis=0))
    # The paper's windows: one label per 512-step history, the label last.
    inputs, targets = make_sequences(arrays, ["b0", "b1"], norm, length=1, burn_in=15, dtype=np.float64)
    assert inputs.shape == (n, 16, 2) and np.all(targets["mask"][:, :-1] == 0) and np.all(targets["mask"][:, -1] == 1)
