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
