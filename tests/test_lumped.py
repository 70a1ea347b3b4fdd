"""The lumped press model's pure core on data drawn from the model itself: variable
projection recovers the linear parameters at the truth, misplaced onsets or lag
show, and Levenberg-Marquardt recovers the shape, onsets and lag."""

import dataclasses
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hydrotact.sysid._solve import solve_least_squares
from hydrotact.sysid.lumped._lumped import LAG_BOUND, ONSET_HALF_RANGE, PressLayout, calc_press_jacobian, calc_press_predictions, calc_press_residuals, press_residual_fn
from hydrotact.sysid.lumped._onset_scan import ONSET_SCAN, SCAN_MIN_GAIN, _lowest_minima, _site_scan, projection_at, scan_constants
from hydrotact.sysid.lumped._press_data import drift_basis
from hydrotact.sysid.lumped._press_solve import solve_press_scanned
from hydrotact.sysid.lumped._press_windows import CONTINUATION_POWER, DEPTH_SCALE, POWERS, _law_inputs, calc_bases, calc_depths, calc_site_bases, make_press_data, window_decay
from hydrotact.visco import Prony, calc_hereditary_integral

SHAPE = Prony(jnp.asarray(1.0), jnp.asarray([0.1, 0.15]), jnp.asarray([0.5, 5.0]))


def _presses(rng, num_samples, num_presses, hold):
    """A jittered 16 Hz clock with presses of 1.2 mm travel (0.8 s ramps)."""
    t = np.cumsum(1 / 16 + 0.01 * rng.standard_normal(num_samples).clip(-3, 3))
    t -= t[0]
    travel, press = np.zeros_like(t), -np.ones(len(t), int)
    period = t[-1] / num_presses
    for p in range(num_presses):
        a = p * period + 2.0
        ramp = np.clip((t - a) / 0.8, 0, 1) * np.clip((a + 0.8 + hold + 0.8 - t) / 0.8, 0, 1)
        travel = np.maximum(travel, 1.2e-3 * ramp)
        press[(t > a - 0.1) & (t < a + hold + 1.7)] = p
    return t, travel, press


def _amplitudes(rng, num_channels, num_sites):
    """(C, S, J) laws that are mostly Hertz with some stiffening, as a channel under a skin."""
    amplitudes = np.zeros((num_channels, num_sites, len(POWERS)))
    amplitudes[..., POWERS.index(1.5)] = rng.uniform(500, 3000, (num_channels, num_sites))
    amplitudes[..., POWERS.index(3.0)] = rng.uniform(0, 300, (num_channels, num_sites))
    return amplitudes


def _data(t, travel, press, sites, observed, noise, num_sites):
    return make_press_data(t, travel, press, sites, observed, np.full(observed.shape, 1 / noise), drift_basis(t, 30.0), num_sites)


def _model_log(rng, num_samples, num_presses, num_sites, num_channels, hold):
    """A log drawn from the model itself (sites in turn, lag 0.05 s, 2 Pa noise):
    (data, onsets, amplitudes, baseline coefficients)."""
    t, travel, press = _presses(rng, num_samples, num_presses, hold)
    sites = np.arange(num_presses) % num_sites
    onsets = rng.uniform(0.4e-3, 0.6e-3, num_presses)
    amplitudes = _amplitudes(rng, num_channels, num_sites)
    blank = _data(t, travel, press, sites, np.zeros((len(t), num_channels)), 1.0, num_sites)
    baseline = rng.normal(0, 300, (num_channels, blank.baseline.shape[1])) + 101325.0
    clean = np.asarray(calc_press_predictions(SHAPE, jnp.asarray(onsets), 0.05, jnp.asarray(baseline), jnp.asarray(amplitudes), blank))
    noise = 2.0
    return _data(t, travel, press, sites, clean + noise * rng.standard_normal(clean.shape), noise, num_sites), onsets, amplitudes, baseline


def test_press_windows_give_the_integral_of_the_site_split_law():
    """The bases from each press's window and free decay equal the hereditary
    integral of the whole site-split input, where the windows tie: a press from the
    first sample, back-to-back presses at one site and at two, a press to the last
    sample, one whose samples fell in a gap (none), and a site that sees two presses
    with a rest between (site 1: its memory, negative while the skin recovers, runs
    into its second press)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(np.full(60, 1 / 16) + 0.005 * rng.standard_normal(60))
    travel = 1e-3 * np.abs(np.sin(t))
    press = -np.ones(60, int)
    press[0:8], press[8:15], press[15:22], press[30:40], press[50:60] = 0, 1, 2, 4, 5  # press 3 has no samples
    sites = np.array([0, 0, 1, 2, 1, 0])
    data = make_press_data(t, travel, press, sites, np.zeros((60, 1)), np.ones((60, 1)), np.ones((60, 1)), 3)
    assert [int(n) for n in data.window_last] == [8, 17, 26, 27, 39, 50]  # windows of 9, 9, 9, 1 (no samples), 12, 11
    depths = calc_depths(data, jnp.asarray(np.full(6, 0.2e-3)), 0.0)
    inputs = (jnp.asarray(sites)[jnp.maximum(data.press, 0)][:, None] == jnp.arange(3)[None, :]) & (data.press >= 0)[:, None]
    law = (depths / DEPTH_SCALE)[:, None] ** jnp.asarray(POWERS)[None, :]
    expected = calc_hereditary_integral(SHAPE, data.times, inputs[:, :, None] * law[:, None, :])
    np.testing.assert_allclose(np.asarray(calc_bases(SHAPE, depths, data)), np.asarray(expected), rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(expected))))
    assert float(jnp.max(expected[22:30, 1])) < 0.0 and float(jnp.max(expected[40:, 1])) < 0.0  # site 1 recovers after each press
    assert float(jnp.max(jnp.abs(expected[:, 2]))) == 0.0  # site 2 saw only the press without samples
    # One site's bases alone (the onset scan's), the windows' decay given.
    for site in range(3):
        alone = calc_site_bases(SHAPE, depths, data, jnp.asarray(site), window_decay(SHAPE.taus, data)[0])
        np.testing.assert_allclose(np.asarray(alone), np.asarray(expected[:, site]), rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(expected))))
    # Past each site's reach (the deepest depth its laws were fitted to), every power
    # goes on as its value there times (δ/reach)^CONTINUATION_POWER; within, as fitted.
    reach = jnp.asarray([0.5e-3, 0.3e-3, 2e-3])
    site = np.asarray(sites)[np.maximum(np.asarray(data.press), 0)]
    limit = np.where(np.asarray(data.press) >= 0, np.asarray(reach)[site], 0.0)
    plain = np.asarray(depths)
    assert (plain > limit).sum() >= 10 and ((plain > 0) & (plain <= limit)).sum() >= 10  # both sides are tried
    held = np.minimum(plain, limit)
    continued = np.where(plain > limit, (plain / np.where(plain > limit, limit, 1.0)) ** CONTINUATION_POWER, 1.0)
    law = np.where(plain[:, None] > 0, (held / DEPTH_SCALE)[:, None] ** np.asarray(POWERS)[None, :] * continued[:, None], 0.0)
    expected = calc_hereditary_integral(SHAPE, data.times, inputs[:, :, None] * jnp.asarray(law)[:, None, :])
    np.testing.assert_allclose(np.asarray(calc_bases(SHAPE, depths, data, reach)), np.asarray(expected), rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(expected))))
    # Continuous at the reach, and a law's sign there is its sign beyond.
    at, past = jnp.asarray([0.3e-3, 0.3e-3 + 1e-12]), jnp.asarray([0.3e-3, 0.6e-3])
    one = make_press_data(np.arange(2.0), np.zeros(2), np.zeros(2, int), np.array([1]), np.zeros((2, 1)), np.ones((2, 1)), np.ones((2, 1)), 3)
    edge = _law_inputs(at, one, reach)[0][:, 1, :]
    np.testing.assert_allclose(np.asarray(edge[1]), np.asarray(edge[0]), rtol=1e-8)
    # 3 (δ/1 mm)^1.5 − 4 (δ/1 mm)^2: +0.133 at the reach, 0.3 mm; the powers go on to
    # −0.046 at 0.6 mm, the continuation to 0.133 x 2^p.
    cancelling = jnp.asarray([3.0, -4.0, 0.0, 0.0])
    values = _law_inputs(past, one, reach)[0][:, 1, :] @ cancelling
    powers = _law_inputs(past, one)[0][:, 1, :] @ cancelling
    assert float(powers[1]) < 0.0 < float(values[0])
    np.testing.assert_allclose(np.asarray(values), [float(powers[0]), float(powers[0]) * 2.0**CONTINUATION_POWER], rtol=1e-12)


def test_projection_at_the_truth_leaves_the_noise():
    rng = np.random.default_rng(0)
    data, onsets, amplitudes, baseline = _model_log(rng, 2000, 8, 4, 3, 8.0)
    residuals, drifts, fitted = calc_press_residuals(SHAPE, (jnp.asarray(onsets),), (jnp.asarray(0.05),), (data,))
    assert 0.95 < float(jnp.std(residuals[0])) < 1.05
    np.testing.assert_allclose(np.asarray(drifts[0]), baseline, atol=3.0)
    # The powers are nearly collinear over 0-0.7 mm: the laws, not each coefficient, are determined.
    depths = np.linspace(0.05, 0.7, 14)[:, None] ** np.asarray(POWERS)[None, :]
    np.testing.assert_allclose(np.einsum("dj,csj->csd", depths, np.asarray(fitted)), np.einsum("dj,csj->csd", depths, amplitudes), rtol=0.01, atol=2.0)
    # A flexible law absorbs much of a shifted onset (only the first samples of
    # contact tell), a lag not.
    shifted, _, _ = calc_press_residuals(SHAPE, (jnp.asarray(onsets) + 100e-6,), (jnp.asarray(0.05),), (data,))
    unlagged, _, _ = calc_press_residuals(SHAPE, (jnp.asarray(onsets),), (jnp.asarray(0.0),), (data,))
    assert float(jnp.std(shifted[0])) > 1.1 and float(jnp.std(unlagged[0])) > 5.0
    gradient = jax.jacfwd(lambda o: calc_press_residuals(SHAPE, (o,), (jnp.asarray(0.05),), (data,))[0][0].sum())(jnp.asarray(onsets))
    assert bool(jnp.all(jnp.isfinite(gradient)))


def test_the_nonlinear_fit_recovers_shape_onsets_and_lag():
    rng = np.random.default_rng(1)
    num_presses = 6
    data, onsets, _, _ = _model_log(rng, 1600, num_presses, 3, 2, 10.0)
    layout = PressLayout(2, (num_presses,), True)
    start = jnp.asarray(onsets + rng.uniform(-80e-6, 80e-6, num_presses))
    x0 = jnp.concatenate([jnp.log(jnp.asarray([0.05, 0.05])), jnp.log(jnp.asarray([0.3, 3.0])), jnp.zeros(num_presses), jnp.zeros(1)])
    args = ((data,), (start,), (0.0,))
    solution = solve_press_scanned(layout, None, 200, x0, args)[0]
    shape, fitted_onsets, lags = layout.unpack(solution.value, (start,), (0.0,))
    order = np.argsort(np.asarray(shape.taus))  # the terms may come back in either order
    np.testing.assert_allclose(np.asarray(shape.taus)[order], [0.5, 5.0], rtol=0.05)
    np.testing.assert_allclose(np.asarray(shape.moduli)[order], [0.1, 0.15], rtol=0.05)
    # Onsets are the weakest: a press's first samples of contact carry them.
    np.testing.assert_allclose(np.asarray(fitted_onsets[0]), onsets, atol=0.1e-3)
    assert abs(float(lags[0]) - 0.05) < 0.005


def test_a_term_switched_off_is_the_fit_without_it():
    """A layout of 3 terms with the third off (PressLayout.active: what --terms auto
    runs, one compiled program for every count) is the 2-term model: the same
    residuals, the same Jacobian in the terms that are on and 0 in the two columns
    of the term that is off, and a solve from the same start ends where the 2-term
    solve does, the switched-off term where it started."""
    rng = np.random.default_rng(1)
    num_presses = 6
    data, onsets, _, _ = _model_log(rng, 1600, num_presses, 3, 2, 10.0)
    args = ((data,), (jnp.asarray(onsets + 60e-6),), (0.0,))
    two = PressLayout(2, (num_presses,), True)
    three = PressLayout(3, (num_presses,), True, jnp.asarray([1.0, 1.0, 0.0]))
    small, keep = three.without_inactive()
    assert small == two and list(keep) == [0, 1, 3, 4] + list(range(6, 6 + num_presses + 1))
    x2 = jnp.concatenate([jnp.log(jnp.asarray([0.08, 0.2])), jnp.log(jnp.asarray([0.4, 6.0])), jnp.asarray(rng.normal(0, 0.3, num_presses)), jnp.asarray([0.1])])
    x3 = jnp.zeros(three.size).at[jnp.asarray(keep)].set(x2).at[2].set(jnp.log(0.3)).at[5].set(jnp.log(30.0))
    value2, jacobian2 = calc_press_jacobian(two, x2, args)
    value3, jacobian3 = calc_press_jacobian(three, x3, args)
    np.testing.assert_allclose(np.asarray(value3), np.asarray(value2), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(np.asarray(jacobian3)[:, keep], np.asarray(jacobian2), rtol=1e-8, atol=1e-8 * float(jnp.max(jnp.abs(jacobian2))))
    assert not np.any(np.asarray(jacobian3)[:, [2, 5]])
    start2 = jnp.concatenate([jnp.log(jnp.asarray([0.05, 0.05])), jnp.log(jnp.asarray([0.3, 3.0])), jnp.zeros(num_presses + 1)])
    start3 = jnp.zeros(three.size).at[jnp.asarray(keep)].set(start2).at[2].set(jnp.log(0.3)).at[5].set(jnp.log(30.0))
    solved2 = solve_least_squares(press_residual_fn(two), start2, args, max_steps=200)
    solved3 = solve_least_squares(press_residual_fn(three), start3, args, max_steps=200)
    assert bool(solved2.converged) and bool(solved3.converged)
    # each solve stops once its next step is under xtol (1 + |x|inf) (1e-6 here): the two
    # paths (their damping differs with the idle columns) end within that of each other
    # (4.2e-6 measured on an AMD EPYC; under 1e-6 on the Intel Xeon)
    np.testing.assert_allclose(np.asarray(solved3.value)[keep], np.asarray(solved2.value), atol=2e-6 * (1.0 + float(np.max(np.abs(solved2.value)))))
    assert np.asarray(solved3.value)[2] == float(start3[2]) and np.asarray(solved3.value)[5] == float(start3[5])


def test_the_site_onset_scan_leaves_a_minimum_where_a_sites_presses_all_start_early():
    """The trap the scan is for, built on purpose: the log of the test above with
    site 0's onsets started 150 µm early (both of its presses), the rest at the
    truth (the shape and lag too). Levenberg-Marquardt alone stays there (the law
    takes up the shift): a χ² of 3153.7 against 3108.3 from the true onsets, over
    3200 residuals, a reduced χ² near 1 that no threshold on the fit's quality sees;
    the scanned solve reaches the truth's minimum."""
    rng = np.random.default_rng(1)
    num_presses = 6
    data, onsets, _, _ = _model_log(rng, 1600, num_presses, 3, 2, 10.0)
    layout = PressLayout(2, (num_presses,), True)
    start = jnp.asarray(onsets - 150e-6 * (np.asarray(data.press_site) == 0))
    x0 = jnp.concatenate([jnp.log(jnp.asarray([0.1, 0.15])), jnp.log(jnp.asarray([0.5, 5.0])), jnp.zeros(num_presses), jnp.atleast_1d(jnp.arctanh(0.05 / LAG_BOUND))])
    args = ((data,), (start,), (0.0,))
    residual_fn = press_residual_fn(layout)

    def cost(x):
        return float(jnp.sum(residual_fn(x, args) ** 2))

    alone = solve_least_squares(residual_fn, x0, args, max_steps=200)
    scanned = solve_press_scanned(layout, None, 200, x0, args)[0]
    truth = solve_least_squares(residual_fn, x0.at[4:10].set(jnp.arctanh((jnp.asarray(onsets) - start) / ONSET_HALF_RANGE)), args, max_steps=200)
    num_residuals = int(np.sum(np.asarray(data.weights) > 0))
    assert cost(alone.value) > cost(truth.value) + 20.0 and cost(alone.value) < 1.1 * num_residuals
    assert cost(scanned.value) < cost(truth.value) + 1e-3 * num_residuals
    np.testing.assert_allclose(np.asarray(layout.unpack(scanned.value, (start,), (0.0,))[1][0]), onsets, atol=0.03e-3)
    assert np.all(np.abs(np.asarray(layout.unpack(alone.value, (start,), (0.0,))[1][0]) - onsets)[::3] > 0.1e-3)  # site 0's presses


def test_the_scan_judges_only_shifts_that_lower_the_chi_square_significantly():
    """A site's scan with local minima 1.0, 3.0 and 37.0 below the unmoved shift (the
    trap's gain above): the whole projection judges the trap's alone, and every
    minimum below the unmoved shift with no threshold; a scale (the χ² per residual)
    raises the threshold with it."""
    unmoved = 12
    costs = np.full(25, 100.0)
    costs[unmoved] = 90.0
    costs[[3, 8, 20]] = 90.0 - np.asarray([1.0, 37.0, 3.0])
    assert SCAN_MIN_GAIN == pytest.approx(3.84, abs=0.01)  # χ²(1)'s 5 % point
    assert _lowest_minima(costs, unmoved, SCAN_MIN_GAIN) == [8]
    assert _lowest_minima(costs, unmoved) == [8, 20, 3]
    assert _lowest_minima(costs, unmoved, SCAN_MIN_GAIN * 10.0) == []


def test_the_scans_projected_baselines_give_the_refitted_chi_square():
    """The onset scan projects each log's baseline out of a shift's solve (its Gram
    matrix inverted once per scan) instead of refitting it with the site's law: the
    same χ² for every shift of every site, to rounding, on the trap's log."""
    rng = np.random.default_rng(1)
    num_presses = 6
    data, onsets, _, _ = _model_log(rng, 1600, num_presses, 3, 2, 10.0)
    assert data.drift_from == "all"
    layout = PressLayout(2, (num_presses,), True)
    start = jnp.asarray(onsets - 150e-6 * (np.asarray(data.press_site) == 0))
    x = jnp.concatenate([jnp.log(jnp.asarray([0.1, 0.15])), jnp.log(jnp.asarray([0.5, 5.0])), jnp.zeros(num_presses), jnp.atleast_1d(jnp.arctanh(0.05 / LAG_BOUND))])
    args = ((data,), (start,), (0.0,))
    projection = projection_at(layout, x, args)[1]
    held = scan_constants(layout, x, args)
    offsets = jnp.asarray(ONSET_SCAN)
    for site in range(3):
        projected = np.asarray(_site_scan(layout, x, args, jnp.asarray(site), offsets, projection, held, True))
        refitted = np.asarray(_site_scan(layout, x, args, jnp.asarray(site), offsets, projection, held, False))
        assert np.array_equal(np.isfinite(projected), np.isfinite(refitted)) and np.isfinite(refitted).sum() > 10
        finite = np.isfinite(refitted)
        np.testing.assert_allclose(projected[finite], refitted[finite], rtol=1e-7, atol=1e-6)  # the ridges differ (1e-12 of other matrices)
        assert np.ptp(refitted[finite]) > 10.0  # the shifts do move the χ²


@pytest.mark.parametrize("drift_from", ["unloaded", "all"])
def test_the_hand_jacobian_is_autodiffs_through_the_projection(drift_from):
    """calc_press_jacobian (Golub-Pereyra by hand, each derivative basis integrated
    once) against JAX's forward mode through the plain model and its LU solve, for
    two logs (shared shape, own onsets and lags) away from the truth, with each
    baseline learned out of contact (the block-triangular projection) and jointly.
    They agree to the projection's round-off (the powers are nearly collinear: ~1e-4
    of a column's largest entry); a wrong term, a lost chain factor or another log's
    column would be off by O(1). Channel 0's law at site 1 is fixed at 0 (as for a
    barometer that does not respond there): it stays 0, and its derivative too."""
    rng = np.random.default_rng(2)
    logs = [_model_log(rng, 700, 4, 3, 2, 6.0), _model_log(rng, 600, 3, 3, 2, 5.0)]
    responds = np.ones((2, 3), bool)
    responds[0, 1] = False
    datas = tuple(dataclasses.replace(eqx.tree_at(lambda data: data.responds, log[0], jnp.asarray(responds)), drift_from=drift_from) for log in logs)
    layout = PressLayout(2, (4, 3), True)
    starts = tuple(jnp.asarray(log[1] + rng.uniform(-50e-6, 50e-6, len(log[1]))) for log in logs)
    args = (datas, starts, (0.0, 0.0))
    x = jnp.asarray(np.concatenate([np.log([0.08, 0.2]), np.log([0.4, 6.0]), rng.normal(0, 0.3, 7), [0.2, 0.05]]))

    def plain(x):
        return jnp.concatenate([r.reshape(-1) for r in calc_press_residuals(*layout.unpack(x, starts, (0.0, 0.0)), datas)[0]])

    # one program each: the hand Jacobian with the sensitivity, autodiff's, the amplitudes' derivatives
    value, jacobian, *_, sensitivity = jax.jit(lambda x: calc_press_jacobian(layout, x, args, linear=True))(x)
    plain_value, reference = jax.jit(lambda x: (plain(x), jax.jacfwd(plain)(x)))(x)
    amplitudes = jax.jit(lambda x: calc_press_residuals(*layout.unpack(x, starts, (0.0, 0.0)), datas)[2])
    by_x = np.asarray(jax.jit(jax.jacfwd(amplitudes))(x))
    assert np.all(np.asarray(amplitudes(x))[0, 1] == 0.0) and np.all(np.asarray(amplitudes(x))[1, 1] != 0.0)
    assert np.all(by_x[0, 1] == 0.0)
    np.testing.assert_allclose(np.asarray(value), np.asarray(plain_value), atol=1e-4)
    scale = np.abs(np.asarray(reference)).max(axis=0)
    assert np.all(scale > 0.0)
    np.testing.assert_array_less(np.abs(np.asarray(jacobian - reference)).max(axis=0), 1e-3 * scale)
    # The fit's residual function carries this Jacobian (its forward mode is a
    # product with it; jit's fusions differ only in round-off).
    carried = jax.jit(jax.jacfwd(press_residual_fn(layout)))(x, args)
    np.testing.assert_array_less(np.abs(np.asarray(carried - jacobian)).max(axis=0), 1e-6 * scale)
    # What the amplitudes' covariance is built from: their derivatives in x (against
    # forward mode through the projection), and their block of N⁻¹, which is the
    # covariance of amplitudes solved from readings with the weights' noise: Σ_t
    # (∂A/∂y_t)(∂A/∂y_t)ᵀ / w_t² (reverse mode in the readings).
    steps = np.moveaxis(by_x, -1, 0).reshape(np.asarray(sensitivity.steps).shape)
    np.testing.assert_allclose(np.asarray(sensitivity.steps), steps, atol=1e-3 * np.abs(steps).max())

    def from_readings(observed):
        changed = tuple(eqx.tree_at(lambda data: data.observed, data, y) for data, y in zip(datas, observed))
        return calc_press_residuals(*layout.unpack(x, starts, (0.0, 0.0)), changed)[2]

    by_reading = jax.jit(jax.jacrev(from_readings))(tuple(data.observed for data in datas))  # per log (C, S, J, T, C)
    for c in range(len(responds)):
        block = sum(
            np.einsum("st,t,rt->sr", np.asarray(d)[c, ..., c].reshape(12, -1), 1.0 / np.asarray(data.weights)[:, c] ** 2, np.asarray(d)[c, ..., c].reshape(12, -1))
            for d, data in zip(by_reading, datas)
        )
        # to 1e-4 (the nearly collinear powers: N is ill-conditioned); a wrong block would be off by O(1)
        np.testing.assert_allclose(np.asarray(sensitivity.inverse)[c], block, rtol=1e-3, atol=1e-6 * np.abs(block).max())
    assert np.all(np.asarray(sensitivity.inverse)[0, 4:8] == 0.0)  # channel 0's law at site 1 is fixed at 0


CONCURRENT_SOLVES = """
import sys, jax, jax.numpy as jnp, numpy as np
from hydrotact import _linalg
jax.config.update("jax_enable_x64", True)
solve = _linalg.solve if sys.argv[1] == "hydrotact" else lambda a, b: jnp.linalg.solve(a, b[..., None])[..., 0]
rng = np.random.default_rng(0)
a = rng.normal(size=(8, 4, 60, 60))
a = a @ np.swapaxes(a, -1, -2) + 60 * np.eye(60)
b = rng.normal(size=(8, 4, 60))
run = jax.jit(lambda a, b: [solve(a[k], b[k]) for k in range(8)])  # eight independent batched solves in one program
for step in range(20):
    jax.block_until_ready(run(jnp.asarray(a) + step, jnp.asarray(b)))
print("done")
"""


def test_batched_solves_run_one_matrix_at_a_time_and_never_deadlock():
    """The cause of the lumped fit that hung: jaxlib 0.10's CPU LAPACK splits a batch
    of matrices over XLA's thread pool and blocks the pool thread that called it;
    eight independent batched solves in one program (XLA runs them at once) leave no
    thread to run the pieces, and the process stops for good, using no CPU. Through
    hydrotact._linalg (one matrix at a time) the same program finishes; the fit's
    programs hold no batched LAPACK call at all."""
    import subprocess
    import sys
    import time

    from helpers import batched_lapack_calls

    from hydrotact.sysid.lumped._press_projection import solve_baselines

    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CONCURRENT_SOLVES, "hydrotact"], capture_output=True, text=True, timeout=120)
    elapsed = time.perf_counter() - started
    assert done.returncode == 0 and done.stdout.strip() == "done", done.stderr
    if tuple(int(p) for p in jax.__version__.split(".")[:3]) < (0, 11, 2):  # compiled out of later jaxlibs
        with pytest.raises(subprocess.TimeoutExpired):  # stuck, not slow: still running at 5 x the other's whole run
            subprocess.run([sys.executable, "-c", CONCURRENT_SOLVES, "jax"], capture_output=True, text=True, timeout=max(10.0, 5.0 * elapsed))
    rng = np.random.default_rng(5)
    logs = [_model_log(rng, 300, 3, 2, 2, 4.0), _model_log(rng, 300, 2, 2, 2, 4.0)]
    layout = PressLayout(2, (3, 2), True)
    datas = tuple(log[0] for log in logs)
    args = (datas, tuple(jnp.asarray(log[1]) for log in logs), (0.0, 0.0))
    x = jnp.asarray(np.concatenate([np.log([0.1, 0.2]), np.log([0.5, 5.0]), np.zeros(5), [0.1, 0.1]]))
    programs = {
        "jacobian": jax.make_jaxpr(lambda x: calc_press_jacobian(layout, x, args, linear=True))(x),
        "solver's Jacobian": jax.make_jaxpr(jax.jacfwd(press_residual_fn(layout)))(x, args),
        "baselines": jax.make_jaxpr(solve_baselines)(datas[0].baseline, datas[0].observed, datas[0].weights > 0),
    }
    for name, program in programs.items():
        assert batched_lapack_calls(program) == [], name


def test_the_onset_scans_shifts_do_not_depend_on_the_importers_precision():
    """ONSET_SCAN is made at import: a caller who imports hydrotact before enabling
    float64 (as a notebook may) gets the same shifts as the command line, to the bit
    (float32-rounded shifts took the three-log benchmark fit down another path)."""
    import subprocess
    import sys

    code = "import hydrotact.sysid.lumped._onset_scan as s; print(repr(s.ONSET_SCAN))"
    shown = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**os.environ, "JAX_ENABLE_X64": "0"}, check=True).stdout
    with jax.enable_x64(True):
        assert eval(shown) == tuple(float(v) for v in jnp.linspace(-300e-6, 300e-6, 25))
