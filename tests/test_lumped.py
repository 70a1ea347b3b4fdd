"""The lumped press model (work in progress for issue 13): variable projection
recovers the linear parameters at the truth, and misplaced onsets or lag show."""

import jax
import jax.numpy as jnp
import numpy as np

from hydrotact.sysid._lumped import PressData, calc_press_predictions, calc_press_residuals
from hydrotact.visco import Prony


def test_projection_at_the_truth_leaves_the_noise():
    rng = np.random.default_rng(0)
    t = np.cumsum(1 / 16 + 0.01 * rng.standard_normal(2000).clip(-3, 3))
    t -= t[0]
    P, S, C = 8, 4, 3
    travel, press = np.zeros_like(t), -np.ones(len(t), int)
    period = t[-1] / P
    for p in range(P):
        a = p * period + 2.0
        ramp = np.clip((t - a) / 0.8, 0, 1) * np.clip((a + 0.8 + 8.0 + 0.8 - t) / 0.8, 0, 1)
        travel = np.maximum(travel, 1.2e-3 * ramp)
        press[(t > a - 0.1) & (t < a + 9.7)] = p
    press_site = np.arange(P) % S
    onsets = rng.uniform(0.4e-3, 0.6e-3, P)
    shape = Prony(jnp.asarray(1.0), jnp.asarray([0.1, 0.15]), jnp.asarray([0.5, 5.0]))
    exps = jnp.asarray([1.5, 1.3, 2.0])
    amps = rng.uniform(500, 3000, (C, S))
    coef = np.concatenate([np.full((C, 1), 101325.0), np.array([[300.0], [-800.0], [50.0]]), amps], axis=1)
    data0 = PressData(jnp.asarray(t), jnp.asarray(travel), jnp.asarray(press), jnp.asarray(press_site), jnp.zeros((len(t), C)), jnp.ones((len(t), C)), S, True)
    clean = np.asarray(calc_press_predictions(shape, exps, jnp.asarray(onsets), 0.05, jnp.asarray(coef), data0))
    noise = 2.0
    obs = clean + noise * rng.standard_normal(clean.shape)
    data = PressData(jnp.asarray(t), jnp.asarray(travel), jnp.asarray(press), jnp.asarray(press_site), jnp.asarray(obs), jnp.full((len(t), C), 1 / noise), S, True)
    r, c = calc_press_residuals(shape, exps, jnp.asarray(onsets), 0.05, data)
    assert 0.95 < float(jnp.std(r)) < 1.05
    np.testing.assert_allclose(np.asarray(c)[:, 2:], amps, rtol=5e-3)
    r2, _ = calc_press_residuals(shape, exps, jnp.asarray(onsets) + 20e-6, 0.05, data)
    r3, _ = calc_press_residuals(shape, exps, jnp.asarray(onsets), 0.0, data)
    assert float(jnp.std(r2)) > 2.0 and float(jnp.std(r3)) > 5.0
    g = jax.jacfwd(lambda o: calc_press_residuals(shape, exps, o, 0.05, data)[0].sum())(jnp.asarray(onsets))
    assert bool(jnp.all(jnp.isfinite(g)))


def test_the_nonlinear_fit_recovers_shape_exponents_onsets_and_lag():
    from hydrotact.sysid._lumped import EXPONENT_RANGE, PressLayout, press_residual_fn
    from hydrotact.sysid._solve import solve_least_squares

    rng = np.random.default_rng(1)
    t = np.cumsum(1 / 16 + 0.01 * rng.standard_normal(1600).clip(-3, 3))
    t -= t[0]
    num_presses, num_sites, num_channels = 6, 3, 2
    travel, press = np.zeros_like(t), -np.ones(len(t), int)
    period = t[-1] / num_presses
    for p in range(num_presses):
        a = p * period + 2.0
        ramp = np.clip((t - a) / 0.8, 0, 1) * np.clip((a + 0.8 + 10.0 + 0.8 - t) / 0.8, 0, 1)
        travel = np.maximum(travel, 1.2e-3 * ramp)
        press[(t > a - 0.1) & (t < a + 11.7)] = p
    sites = np.arange(num_presses) % num_sites
    onsets = rng.uniform(0.4e-3, 0.6e-3, num_presses)
    shape = Prony(jnp.asarray(1.0), jnp.asarray([0.1, 0.15]), jnp.asarray([0.5, 5.0]))
    exponents = jnp.asarray([1.5, 1.8])
    amplitudes = rng.uniform(1000, 3000, (num_channels, num_sites))
    coefficients = np.concatenate([np.full((num_channels, 1), 101325.0), np.array([[300.0], [-800.0]]), amplitudes], axis=1)
    blank = PressData(jnp.asarray(t), jnp.asarray(travel), jnp.asarray(press), jnp.asarray(sites), jnp.zeros((len(t), num_channels)), jnp.ones((len(t), num_channels)), num_sites, True)
    clean = np.asarray(calc_press_predictions(shape, exponents, jnp.asarray(onsets), 0.05, jnp.asarray(coefficients), blank))
    noise = 2.0
    data = PressData(blank.times, blank.travel, blank.press, blank.press_site, jnp.asarray(clean + noise * rng.standard_normal(clean.shape)), jnp.full(clean.shape, 1 / noise), num_sites, True)
    layout = PressLayout(2, num_channels, num_presses, True)
    start = jnp.asarray(onsets + rng.uniform(-80e-6, 80e-6, num_presses))
    to_unit = (1.5 - EXPONENT_RANGE[0]) / (EXPONENT_RANGE[1] - EXPONENT_RANGE[0])
    x0 = jnp.concatenate([jnp.log(jnp.asarray([0.05, 0.05])), jnp.log(jnp.asarray([0.3, 3.0])), jnp.full(num_channels, np.log(to_unit / (1 - to_unit))), jnp.zeros(num_presses), jnp.zeros(1)])
    solution = solve_least_squares(press_residual_fn(layout), x0, (data, start, 0.0), max_steps=200)
    fitted_shape, fitted_exponents, fitted_onsets, fitted_lag = layout.unpack(solution.value, start, 0.0)
    order = np.argsort(np.asarray(fitted_shape.taus))  # the terms may come back in either order
    np.testing.assert_allclose(np.asarray(fitted_shape.taus)[order], [0.5, 5.0], rtol=0.05)
    np.testing.assert_allclose(np.asarray(fitted_shape.moduli)[order], [0.1, 0.15], rtol=0.05)
    np.testing.assert_allclose(np.asarray(fitted_exponents), [1.5, 1.8], rtol=0.02)
    np.testing.assert_allclose(np.asarray(fitted_onsets), onsets, atol=5e-6)
    assert abs(float(fitted_lag) - 0.05) < 0.005
