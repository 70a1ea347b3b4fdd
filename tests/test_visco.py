"""Viscoelasticity and the barometer signal (hydrotact.visco) against closed forms.

Every reference below is derived by hand from the hereditary integral
p(t) = ∫ E(t − s) du(s), E(t) = E∞ + Σᵢ Eᵢ exp(−t/τᵢ), not from the code:

- a step u0 at t0 gives E(t − t0) u0;
- ramp-and-hold, sinusoid (with its start-up transient) and repeated press/release
  cycles (a geometric series) have closed forms; the update is exact for piecewise-
  linear input, so where the input *is* piecewise linear in the samples the match is to
  round-off, and where it is not (a corner between samples, a smooth sinusoid) the
  error must fall with the expected order;
- a direct O(T²) sum over the linear pieces is a second implementation;
- the two scan methods agree; jit, vmap and grad (against central differences) work.

Everything runs with implicit rank promotion raising (tests/conftest.py); one sample
works with either method.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hydrotact import HydrotactError
from hydrotact.sensors import known_parts
from hydrotact.visco import (
    Prony,
    calc_barometer_readings,
    calc_hereditary_integral,
    calc_kernel_responses_and_derivatives,
    calc_resampled,
    calc_sample_times,
    make_barometer_signal,
    make_prony,
)

METHODS = ("scan", "associative")
E_INF = 8.0e4
MODULI = (3.0e4, 2.0e4, 1.0e4)
TAUS = (0.03, 0.25, 1.5)


# Compiled once per (shapes, method) and shared by the tests: eager associative scans
# dispatch op by op and are slow.
_response = jax.jit(calc_hereditary_integral, static_argnames="method")
_readings = jax.jit(calc_barometer_readings, static_argnames="quantise")
_resampled = jax.jit(calc_resampled)


@pytest.fixture
def prony():
    return make_prony(E_INF, MODULI, TAUS)


def _relaxation(t, e_inf=E_INF, moduli=MODULI, taus=TAUS):
    """E(t) in numpy, written out (the reference, not Prony.calc_relaxation_modulus)."""
    t = np.asarray(t, dtype=np.float64)
    return e_inf + sum(m * np.exp(-t / tau) for m, tau in zip(moduli, taus))


def _random_times(rng, count, mean_step, start=0.0, spread=0.9):
    """Strictly increasing, non-uniform: steps in mean_step · [1 − spread, 1 + spread]."""
    steps = mean_step * rng.uniform(1.0 - spread, 1.0 + spread, count - 1)
    return start + np.concatenate([[0.0], np.cumsum(steps)])


def _times_through(rng, breakpoints, per_piece):
    """Non-uniform times that hit every breakpoint, `per_piece` random points between."""
    pieces = []
    for a, b in zip(breakpoints[:-1], breakpoints[1:]):
        inner = np.sort(rng.uniform(a, b, per_piece))
        pieces.append(np.concatenate([[a], inner]))
    return np.concatenate([*pieces, [breakpoints[-1]]])


def _scale_close(actual, expected, rtol):
    """|actual − expected| ≤ rtol · max|expected| everywhere."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    error = np.max(np.abs(actual - expected))
    scale = np.max(np.abs(expected))
    assert error <= rtol * scale, f"max error {error:.3e} > {rtol:g} × {scale:.3e}"


def _orders(step_sizes, errors):
    step_sizes, errors = np.asarray(step_sizes), np.asarray(errors)
    return np.log(errors[:-1] / errors[1:]) / np.log(step_sizes[:-1] / step_sizes[1:])


# --- make_prony and Prony -------------------------------------------------------------


def test_make_prony_sorts_by_tau():
    prony = make_prony(1e5, [1.0e3, 2.0e3, 3.0e3], [2.0, 0.1, 0.5])
    np.testing.assert_array_equal(np.asarray(prony.taus), [0.1, 0.5, 2.0])
    np.testing.assert_array_equal(np.asarray(prony.moduli), [2.0e3, 3.0e3, 1.0e3])
    assert float(prony.long_term_modulus) == 1e5
    assert isinstance(prony, Prony) and prony.num_terms == 3
    assert prony.moduli.dtype == prony.taus.dtype == jnp.float64


def test_make_prony_without_terms_is_elastic(rng):
    prony = make_prony(5e4)
    assert prony.num_terms == 0 and float(prony.instantaneous_modulus) == 5e4
    times = _random_times(rng, 20, 0.1)
    values = rng.normal(size=(20, 3))
    for method in METHODS:
        np.testing.assert_allclose(_response(prony, times, values, method=method), 5e4 * values, rtol=1e-15)


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        ((0.0, [1.0], [1.0]), ["long-term modulus", "positive"]),
        ((-1e5, [1.0], [1.0]), ["long-term modulus", "-100000"]),
        ((float("nan"), [1.0], [1.0]), ["long-term modulus"]),
        ((float("inf"), [1.0], [1.0]), ["long-term modulus"]),
        ((1e5, [1e4, -5.0], [0.1, 0.2]), ["Prony term 2", "modulus", "non-negative", "-5"]),
        ((1e5, [float("nan")], [0.1]), ["Prony term 1", "modulus"]),
        ((1e5, [1e4, 1e4, 1e4], [0.1, 0.2, 0.0]), ["Prony term 3", "relaxation time", "positive"]),
        ((1e5, [1e4, 1e4], [-0.2, 0.1]), ["Prony term 1", "relaxation time", "-0.2"]),
        ((1e5, [1e4, 1e4], [0.1, float("nan")]), ["Prony term 2", "relaxation time"]),
        ((1e5, [1e4], [float("inf")]), ["Prony term 1", "relaxation time"]),
        ((1e5, [1e4, 2e4], [0.1]), ["2 Prony moduli but 1 relaxation times"]),
        ((1e5, [1e4], [0.1, 0.2]), ["1 Prony moduli but 2 relaxation times"]),
    ],
    ids=[
        "zero E_inf", "negative E_inf", "nan E_inf", "inf E_inf", "negative modulus", "nan modulus",
        "zero tau", "negative tau", "nan tau", "inf tau", "more moduli", "more taus",
    ],
)
def test_make_prony_rejects(args, fragments):
    with pytest.raises(HydrotactError) as info:
        make_prony(*args, source="rubber.json")
    message = str(info.value)
    assert message.startswith("rubber.json: ") and "\n" not in message, message
    for fragment in fragments:
        assert fragment in message, (fragment, message)


def test_make_prony_allows_zero_modulus():
    prony = make_prony(1e5, [0.0, 1e4], [0.1, 0.2])
    assert float(prony.instantaneous_modulus) == 1.1e5


def test_relaxation_modulus_limits(prony):
    instantaneous = E_INF + sum(MODULI)
    assert float(prony.instantaneous_modulus) == pytest.approx(instantaneous, rel=1e-15)
    assert float(prony.calc_relaxation_modulus(0.0)) == pytest.approx(instantaneous, rel=1e-15)
    assert float(prony.calc_relaxation_modulus(1e3 * max(TAUS))) == pytest.approx(E_INF, rel=1e-15)
    assert float(prony.calc_relaxation_modulus(TAUS[1])) == pytest.approx(float(_relaxation(TAUS[1])), rel=1e-14)


def test_relaxation_modulus_at_array_times(prony, rng):
    times = rng.uniform(0.0, 3.0, size=(4, 5))
    values = prony.calc_relaxation_modulus(times)
    assert values.shape == (4, 5)
    np.testing.assert_allclose(values, _relaxation(times), rtol=1e-14)
    assert np.all(np.diff(np.asarray(prony.calc_relaxation_modulus(np.linspace(0, 10, 50)))) < 0)


# --- the known bugs -------------------------------------------------------------------

def test_relaxation_modulus_rank_promotion(prony):
    with jax.numpy_rank_promotion("raise"):
        assert prony.calc_relaxation_modulus(np.linspace(0.0, 1.0, 5)).shape == (5,)


@pytest.mark.parametrize("method", METHODS)
def test_hereditary_integral_rank_promotion(prony, method):
    with jax.numpy_rank_promotion("raise"):
        assert calc_hereditary_integral(prony, np.linspace(0.0, 1.0, 5), np.ones((5, 2)), method=method).shape == (5, 2)


def test_barometer_readings_rank_promotion():
    signal = make_barometer_signal(known_parts()["BMP388"], 3)
    with jax.numpy_rank_promotion("raise"):
        assert calc_barometer_readings(signal, jnp.linspace(0.0, 0.1, 11), jnp.zeros((11, 3))).shape == (11, 3)


def test_resampled_and_scalar_modulus_without_rank_promotion(prony):
    with jax.numpy_rank_promotion("raise"):
        times = jnp.linspace(0.0, 1.0, 5)
        resampled = calc_resampled(times, jnp.ones((5, 2)), jnp.linspace(0.0, 1.0, 7))
        assert resampled.shape == (7, 2)
        prony.calc_relaxation_modulus(0.5)


def test_single_sample_associative(prony):
    response = calc_hereditary_integral(prony, np.array([0.0]), np.ones((1, 2)), method="associative")
    np.testing.assert_allclose(response, E_INF + sum(MODULI), rtol=1e-15)


def test_single_sample_scan(prony):
    response = calc_hereditary_integral(prony, np.array([0.3]), np.full((1, 2), 2.0), method="scan")
    np.testing.assert_allclose(response, 2.0 * (E_INF + sum(MODULI)), rtol=1e-15)


# --- closed forms ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("method", "trailing"),
    [("scan", ()), ("scan", (4,)), ("scan", (2, 3)), ("associative", (2, 3))],
    ids=["scan-T", "scan-TxC", "scan-TxCx3", "associative-TxCx3"],
)
def test_step_gives_relaxation_modulus(prony, rng, method, trailing):
    """u = u0 from t0 on (a step at t0: at rest before) → p(t) = E(t − t0) u0."""
    t0, count = 0.37, 120
    uniform = t0 + 0.02 * np.arange(count)
    # steps from 1e-9 s (≪ τ) to 0.5 s (≫ the shortest τ), in random order
    non_uniform = t0 + np.concatenate([[0.0], np.cumsum(np.exp(rng.uniform(np.log(1e-9), np.log(0.5), count - 1)))])
    for times in (uniform, non_uniform):
        u0 = rng.uniform(-2.0, 2.0, size=trailing)
        values = np.broadcast_to(u0, (count, *trailing))
        response = np.asarray(_response(prony, times, values, method=method))
        expected = _relaxation(times - t0).reshape((count,) + (1,) * len(trailing)) * u0
        assert response.shape == (count, *trailing)
        np.testing.assert_allclose(response, expected, rtol=1e-12)


def _ramp_hold(times, rate, t1):
    """Closed form of p for u = rate · min(t, t1) (t ≥ 0, at rest before 0)."""
    moduli, taus = np.array(MODULI), np.array(TAUS)
    t = np.asarray(times)[:, None]
    ramp = rate * (E_INF * t[:, 0] + np.sum(moduli * taus * (1.0 - np.exp(-t / taus)), axis=1))
    hold = rate * (E_INF * t1 + np.sum(moduli * taus * (np.exp(-(t - t1) / taus) - np.exp(-t / taus)), axis=1))
    return np.where(times <= t1, ramp, hold)


@pytest.mark.parametrize("method", METHODS)
def test_ramp_and_hold_closed_form(rng, prony, method):
    """Ramp at rate r to t1 (a sample), then hold: exact at random non-uniform steps."""
    rate, t1 = 1.7, 0.4
    times = np.concatenate([_times_through(rng, [0.0, 0.1, t1], 15), _times_through(rng, [t1, 1.0, 4.0], 20)[1:]])
    assert np.all(np.diff(times) > 0) and t1 in times
    rates = np.array([1.0, -0.5])  # two channels: the response is linear in u
    values = rate * np.minimum(times, t1)[:, None] * rates
    response = _response(prony, times, values, method=method)
    expected = _ramp_hold(times, rate, t1)[:, None] * rates
    _scale_close(response, expected, 1e-12)
    np.testing.assert_allclose(response[1:], expected[1:], rtol=1e-12)  # and pointwise (p(0) = 0)


def test_ramp_corner_between_samples_converges(prony):
    """t1 = 1/3 s is never a sample of h = 2⁻ᵏ: the sampled input cuts the corner, so
    the response is wrong by O(h²) (a test that can fail, and the order it fails with)."""
    rate, t1, end = 1.0, 1.0 / 3.0, 1.5
    step_sizes = [2.0**-k for k in range(5, 10)]
    errors = []
    for h in step_sizes:
        times = h * np.arange(round(end / h) + 1)
        response = _response(prony, times, rate * np.minimum(times, t1))
        expected = _ramp_hold(times, rate, t1)
        errors.append(np.max(np.abs(np.asarray(response) - expected)) / np.max(np.abs(expected)))
    assert errors[0] > 1e-5, errors  # clearly not round-off: the test can fail
    orders = _orders(step_sizes, errors)
    assert np.all(orders >= 1.5), orders  # ≥ 1 asked; 1.8 while h ~ the shortest τ
    assert orders[-1] == pytest.approx(2.0, abs=0.1)  # the corner's area is O(h²)


def _sine_response(times, omega):
    """Closed form of p for u = sin(ωt) from t = 0 (no step: u(0) = 0), transient included:
    hᵢ = Eᵢ/(1 + ω²τᵢ²) [ω²τᵢ² sin ωt + ωτᵢ cos ωt − ωτᵢ exp(−t/τᵢ)]."""
    t = np.asarray(times)
    response = E_INF * np.sin(omega * t)
    for modulus, tau in zip(MODULI, TAUS):
        wt = omega * tau
        response = response + modulus / (1.0 + wt**2) * (wt**2 * np.sin(omega * t) + wt * np.cos(omega * t) - wt * np.exp(-t / tau))
    return response


def test_sinusoid_converges_with_order_two(prony):
    omega, end = 2.0 * np.pi * 1.0, 3.0
    step_sizes = [1.0 / n for n in (16, 32, 64, 128)]
    errors = []
    for h in step_sizes:
        times = h * np.arange(round(end / h) + 1)
        response = _response(prony, times, np.sin(omega * times))
        expected = _sine_response(times, omega)
        errors.append(np.max(np.abs(np.asarray(response) - expected)) / np.max(np.abs(expected)))
    assert errors[-1] < 1e-4, errors
    np.testing.assert_allclose(_orders(step_sizes, errors), 2.0, atol=0.1)


def test_sinusoid_steady_state_is_complex_modulus(prony):
    """After the transients, p = E' sin ωt + E'' cos ωt: amplitude |E*|, phase lead δ."""
    omega, h, end = 2.0 * np.pi * 2.0, 1.0 / 1024.0, 20.0  # end ≫ τmax = 1.5 s
    times = h * np.arange(round(end / h) + 1)
    response = np.asarray(_response(prony, times, np.sin(omega * times)))
    last = times >= end - 1.0  # the last two periods
    basis = np.stack([np.sin(omega * times[last]), np.cos(omega * times[last])], axis=1)
    (storage, loss), *_ = np.linalg.lstsq(basis, response[last], rcond=None)
    wt = omega * np.array(TAUS)
    moduli = np.array(MODULI)
    expected_storage = E_INF + np.sum(moduli * wt**2 / (1.0 + wt**2))
    expected_loss = np.sum(moduli * wt / (1.0 + wt**2))
    amplitude = math.hypot(expected_storage, expected_loss)
    assert math.hypot(storage, loss) == pytest.approx(amplitude, rel=1e-5)
    assert math.atan2(loss, storage) == pytest.approx(math.atan2(expected_loss, expected_storage), abs=1e-5)
    assert storage == pytest.approx(expected_storage, rel=1e-5)
    assert loss == pytest.approx(expected_loss, rel=1e-4)


def test_press_release_cycles_build_residual_stress(rng):
    """Identical presses (ramp up over a, hold b, ramp down over a, rest to the period P).

    At the end of release k (k = 0, 1, ...) u = 0 and only the term states remain. One
    press seen at its own release end leaves cᵢ = −Eᵢ (U/a) τᵢ (1 − e^{−a/τᵢ})(1 − e^{−(a+b)/τᵢ})
    (negative), which decays by qᵢ = e^{−P/τᵢ} per period, so
    p_k = Σᵢ cᵢ (1 − qᵢ^{k+1}) / (1 − qᵢ): a geometric series to a periodic state.
    """
    e_inf, moduli, taus = 5e4, (2e4, 1e4, 3e4), (0.05, 0.3, 4.0)  # a long τ ≫ the period
    prony = make_prony(e_inf, moduli, taus)
    depth, a, b, period, cycles = 0.8, 0.1, 0.2, 1.0, 12
    breaks = (np.arange(cycles)[:, None] * period + np.array([0.0, a, a + b, 2 * a + b])).ravel()
    breaks = np.append(breaks, cycles * period)
    levels = np.append(np.tile([0.0, depth, depth, 0.0], cycles), 0.0)
    times = _times_through(rng, breaks, 3)
    values = np.interp(times, breaks, levels)[:, None]  # piecewise linear through the breaks
    release_ends = np.searchsorted(times, breaks[3::4])
    assert np.array_equal(times[release_ends], breaks[3::4]) and np.all(values[release_ends] == 0.0)

    for method in METHODS:
        residual = np.asarray(_response(prony, times, values, method=method))[release_ends, 0]
        k = np.arange(cycles)[:, None]
        m, tau = np.array(moduli), np.array(taus)
        single = -m * (depth / a) * tau * (1 - np.exp(-a / tau)) * (1 - np.exp(-(a + b) / tau))
        q = np.exp(-period / tau)
        expected = np.sum(single * (1 - q ** (k + 1)) / (1 - q), axis=1)
        np.testing.assert_allclose(residual, expected, rtol=1e-12)
        assert np.all(residual < 0) and np.all(np.diff(residual) < 0)  # ever more negative
        steady = np.sum(single / (1 - q))
        gaps = residual - steady
        assert np.all(gaps > 0) and np.all(np.diff(gaps) < 0)
        np.testing.assert_allclose(gaps[3:] / gaps[2:-1], q[-1], rtol=1e-4)  # soon the long τ sets the pace


def test_matches_direct_sum_over_pieces(rng, prony):
    """A second implementation: p(tₙ) = E∞ uₙ + Σᵢ Eᵢ [u₀ e^{−(tₙ−t₀)/τᵢ}
    + Σ_{m<n} rₘ τᵢ (e^{−(tₙ−tₘ₊₁)/τᵢ} − e^{−(tₙ−tₘ)/τᵢ})], summed directly (O(T²))."""
    count, channels = 60, 3
    times = _random_times(rng, count, 0.05, start=-0.2)
    values = np.cumsum(rng.normal(size=(count, channels)), axis=0)  # u(t0) ≠ 0: a step too
    slopes = np.diff(values, axis=0) / np.diff(times)[:, None]  # (T-1, C)
    taus, moduli = np.array(TAUS), np.array(MODULI)
    age = times[:, None] - times[None, :]  # tₙ − tₘ
    later = np.arange(count)[:, None] > np.arange(count)[None, :]  # m < n
    expected = E_INF * values
    for modulus, tau in zip(moduli, taus):
        pieces = tau * (np.exp(-np.clip(age[:, 1:], 0, None) / tau) - np.exp(-np.clip(age[:, :-1], 0, None) / tau))
        pieces = np.where(later[:, :-1], pieces, 0.0)  # piece m contributes to n > m
        expected = expected + modulus * (values[0] * np.exp(-(times - times[0]) / tau)[:, None] + pieces @ slopes)
    for method in METHODS:
        _scale_close(_response(prony, times, values, method=method), expected, 1e-12)


# --- the two methods, jit, vmap, grad -------------------------------------------------


def test_methods_agree(rng, prony):
    times = _random_times(rng, 257, 0.01)
    values = rng.normal(size=(257, 3, 2)).cumsum(axis=0)
    scan = _response(prony, times, values, method="scan")
    associative = _response(prony, times, values, method="associative")
    _scale_close(associative, scan, 1e-13)


@pytest.mark.parametrize("method", METHODS)
def test_restarted_sequences_are_independent_runs(rng, prony, method):
    """Sequences concatenated with `restarts` (times stepping back between them, the
    next one starting with a step) give each sequence's own responses and τ
    derivatives, as separate calls do."""
    pieces = [(_random_times(rng, count, 0.05, start=start), rng.normal(size=(count, 3)).cumsum(axis=0)) for count, start in ((40, 0.0), (1, 0.5), (25, 1.0))]
    times = np.concatenate([t for t, _ in pieces])
    values = np.concatenate([v for _, v in pieces])
    restarts = np.concatenate([np.arange(len(t)) == 0 for t, _ in pieces])
    joined = calc_kernel_responses_and_derivatives(prony.taus, jnp.asarray(times), jnp.asarray(values), method, restarts=jnp.asarray(restarts))
    alone = [calc_kernel_responses_and_derivatives(prony.taus, jnp.asarray(t), jnp.asarray(v), method) for t, v in pieces]
    for k in range(2):
        _scale_close(joined[k], np.concatenate([piece[k] for piece in alone]), 1e-13)
    assert calc_kernel_responses_and_derivatives(prony.taus, jnp.asarray(times), jnp.asarray(values), method, with_derivatives=False)[1] is None


def test_unknown_method(prony):
    with pytest.raises(ValueError, match="unknown method 'parallel'"):
        calc_hereditary_integral(prony, np.arange(3.0), np.ones(3), method="parallel")


@pytest.mark.parametrize("method", METHODS)
def test_jit_traces_once(rng, method):
    @jax.jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def response(prony, times, values):
        return calc_hereditary_integral(prony, times, values, method=method)

    times = _random_times(rng, 40, 0.05)
    values = rng.normal(size=(40, 2))
    for e_inf, taus in [(E_INF, TAUS), (2 * E_INF, (0.1, 0.2, 0.3))]:
        prony = make_prony(e_inf, MODULI, taus)
        reference = _response(prony, times, values, method=method)
        np.testing.assert_allclose(response(prony, times + 1.0, values), reference, rtol=1e-13)


def _stack(pronys):
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *pronys)


@pytest.mark.parametrize("method", METHODS)
def test_vmap_over_prony_series_and_inputs(rng, method):
    times = _random_times(rng, 30, 0.05)
    pronys = [make_prony(rng.uniform(1e4, 1e5), rng.uniform(0, 1e4, 3), rng.uniform(0.01, 1.0, 3)) for _ in range(4)]
    values = rng.normal(size=(30, 2)).cumsum(axis=0)
    mapped = jax.jit(jax.vmap(calc_hereditary_integral, in_axes=(0, 0, 0, None)), static_argnums=3)
    # over a batch of Prony series (times and input shared) ...
    batch = mapped(_stack(pronys), np.broadcast_to(times, (4, 30)), np.broadcast_to(values, (4, 30, 2)), method)
    assert batch.shape == (4, 30, 2)
    for one, prony in zip(batch, pronys):
        np.testing.assert_allclose(one, _response(prony, times, values, method=method), rtol=1e-13)
    # ... and over inputs and their times (one Prony series)
    inputs = rng.normal(size=(4, 30, 2)).cumsum(axis=1)
    all_times = np.stack([_random_times(rng, 30, 0.05) for _ in range(4)])
    batch = mapped(_stack([pronys[0]] * 4), all_times, inputs, method)
    for one, t, u in zip(batch, all_times, inputs):
        np.testing.assert_allclose(one, _response(pronys[0], t, u, method=method), rtol=1e-13)


@pytest.mark.parametrize("method", METHODS)
def test_grad_matches_central_differences(rng, prony, method):
    times = _random_times(rng, 50, 0.04)
    values = rng.normal(size=(50, 2)).cumsum(axis=0)
    weights = rng.normal(size=(50, 2))

    @jax.jit
    def loss(prony, values):
        return jnp.sum(weights * calc_hereditary_integral(prony, times, values, method=method))

    grad_prony, grad_values = jax.jit(jax.grad(loss, argnums=(0, 1)))(prony, values)
    # E∞ enters as E∞ u: its gradient is Σ w u exactly.
    assert float(grad_prony.long_term_modulus) == pytest.approx(float(np.sum(weights * values)), rel=1e-12)

    def along(field, direction, step):
        def moved(sign):
            return eqx.tree_at(field, prony, field(prony) + sign * step * direction)

        return (float(loss(moved(1), values)) - float(loss(moved(-1), values))) / (2 * step)

    for name, field, scale in [
        ("E_inf", lambda p: p.long_term_modulus, 1e4),
        ("moduli", lambda p: p.moduli, 1e4),
        ("taus", lambda p: p.taus, 0.01),
    ]:
        direction = rng.normal(size=np.shape(field(prony)))
        direction = float(direction) if direction.ndim == 0 else jnp.asarray(direction)  # E∞ stays weakly typed: no retrace
        analytic = float(jnp.sum(field(grad_prony) * direction))
        numeric = along(field, direction, 1e-6 * scale)
        assert analytic == pytest.approx(numeric, rel=1e-6), name

    direction = rng.normal(size=values.shape)
    step = 1e-3
    numeric = (float(loss(prony, values + step * direction)) - float(loss(prony, values - step * direction))) / (2 * step)
    assert float(np.sum(grad_values * direction)) == pytest.approx(numeric, rel=1e-9)


# --- the barometer signal -------------------------------------------------------------


@pytest.fixture
def part():
    return known_parts()["BMP388"]


def test_signal_defaults_from_part(part):
    signal = make_barometer_signal(part, 4)
    assert signal.num_channels == 4 and signal.rate_hz == 100.0
    assert float(signal.ambient) == 101325.0 and float(signal.lsb) == 0.016 and float(signal.noise_rms) == 0.03
    np.testing.assert_array_equal(signal.gains, np.ones(4))
    np.testing.assert_array_equal(signal.offsets, np.zeros(4))
    np.testing.assert_array_equal(signal.drift_rates, np.zeros(4))


def test_sample_times_at_part_rate(part):
    signal = make_barometer_signal(part, 1)
    times = np.array([0.3, 0.55, 1.3])
    samples = calc_sample_times(times, signal.rate_hz)
    assert len(samples) == 101 and samples[0] == 0.3
    assert samples[-1] == pytest.approx(1.3, abs=1e-12)
    np.testing.assert_allclose(np.diff(samples), 0.01, rtol=0, atol=1e-12)
    assert len(calc_sample_times(np.array([0.0, 0.3]), 100.0)) == 31  # 0.3·100 is 29.999…
    assert len(calc_sample_times(np.array([0.0, 0.0299]), 100.0)) == 3


def test_resampling_linear_data_is_exact(rng):
    times = _random_times(rng, 25, 0.04, start=0.1)
    slopes, intercepts = rng.normal(size=3), rng.normal(size=3)
    values = intercepts + np.outer(times, slopes)
    samples = calc_sample_times(times, 100.0)
    resampled = _resampled(times, values, samples)
    np.testing.assert_allclose(resampled, intercepts + np.outer(samples, slopes), rtol=1e-12, atol=1e-12)
    # piecewise-linear data: the same as numpy's interpolation, channel by channel
    values = rng.normal(size=(25, 3))
    resampled = _resampled(times, values, samples)
    for c in range(3):
        np.testing.assert_allclose(resampled[:, c], np.interp(samples, times, values[:, c]), rtol=1e-13, atol=1e-14)
    # and under vmap and grad (linear in the values); eager: test_resampled_and_scalar_modulus_...
    batch = rng.normal(size=(2, 25, 3))
    mapped = jax.jit(jax.vmap(calc_resampled, in_axes=(None, 0, None)))(times, batch, samples)
    np.testing.assert_allclose(mapped[1], _resampled(times, batch[1], samples), rtol=1e-14, atol=1e-15)
    weights = rng.normal(size=(len(samples), 3))
    grad = jax.jit(jax.grad(lambda v: jnp.sum(weights * calc_resampled(times, v, samples))))(values)
    direction = rng.normal(size=values.shape)
    numeric = float(jnp.sum(weights * _resampled(times, direction, samples)))  # exact for a linear map
    assert float(np.sum(grad * direction)) == pytest.approx(numeric, rel=1e-12)


def test_readings_without_pressure_or_noise(part):
    offsets, drifts = np.array([0.0, 12.3, -7.77]), np.array([0.0, 0.5, -2.0])
    signal = make_barometer_signal(part, 3, offsets=offsets, drift_rates=drifts)
    samples = calc_sample_times(np.array([2.0, 5.0]), signal.rate_hz)
    readings = np.asarray(_readings(signal, jnp.asarray(samples), jnp.zeros((len(samples), 3))))
    exact = 101325.0 + offsets + drifts * (samples - samples[0])[:, None]
    lsb = 0.016
    assert np.max(np.abs(readings - exact)) <= lsb / 2 + 1e-9
    levels = readings / lsb
    np.testing.assert_allclose(levels, np.round(levels), rtol=0, atol=1e-6)  # multiples of the LSB
    unquantised = _readings(signal, jnp.asarray(samples), jnp.zeros((len(samples), 3)), quantise=False)
    np.testing.assert_allclose(unquantised, exact, rtol=1e-15)


def test_readings_scale_with_gains(rng, part):
    gains = np.array([0.5, 1.0, 1.7])
    signal = make_barometer_signal(part, 3, gains=gains, offsets=[1.0, 2.0, 3.0])
    samples = jnp.asarray(calc_sample_times(np.array([0.0, 0.5]), signal.rate_hz))
    pressures = rng.uniform(0.0, 2e3, size=(len(samples), 3))
    readings = _readings(signal, samples, jnp.asarray(pressures), quantise=False)
    np.testing.assert_allclose(np.asarray(readings) - 101325.0 - np.array([1.0, 2.0, 3.0]), gains * pressures, rtol=1e-9)
    quantised = _readings(signal, samples, jnp.asarray(pressures))
    assert np.max(np.abs(np.asarray(quantised) - np.asarray(readings))) <= 0.008 + 1e-9


def test_noise_rms_matches_part(part):
    """1e5 samples, fixed key: the sample RMS is within a few standard errors of the part's."""
    channels, count = 4, 25_000
    signal = make_barometer_signal(part, channels)
    samples = jnp.asarray(calc_sample_times(np.array([0.0, (count - 1) / 100.0]), signal.rate_hz))
    assert samples.shape == (count,)
    pressures = jnp.zeros((count, channels))
    key = jax.random.key(7)
    raw = np.asarray(_readings(signal, samples, pressures, key=key, quantise=False)) - 101325.0
    sigma, n = 0.03, raw.size
    assert abs(raw.mean()) < 5 * sigma / math.sqrt(n)
    assert raw.std() == pytest.approx(sigma, rel=0.01)  # standard error of the std ≈ 0.22 %
    correlation = np.corrcoef(raw.T)[np.triu_indices(channels, 1)]
    assert np.all(np.abs(correlation) < 5 / math.sqrt(count))  # independent channels
    quantised = np.asarray(_readings(signal, samples, pressures, key=key)) - 101325.0
    # Sheppard: rounding to the LSB adds lsb²/12 to the variance
    assert quantised.std() == pytest.approx(math.sqrt(sigma**2 + 0.016**2 / 12), rel=0.01)
    assert np.max(np.abs(quantised - raw)) <= 0.008 + 1e-9
    again = _readings(signal, samples, pressures, key=key)
    np.testing.assert_array_equal(again, quantised + 101325.0)
    other = _readings(signal, samples, pressures, key=jax.random.key(8))
    assert np.mean(np.asarray(other) != np.asarray(again)) > 0.5


def test_readings_jit_vmap_grad(rng, part):
    gains = np.array([0.5, 1.0, 1.7])
    signal = make_barometer_signal(part, 3, gains=gains, drift_rates=[0.1, 0.0, -0.3])
    samples = jnp.asarray(calc_sample_times(np.array([0.0, 0.2]), signal.rate_hz))
    pressures = jnp.asarray(rng.uniform(0.0, 1e3, size=(len(samples), 3)))
    weights = rng.normal(size=pressures.shape)
    key = jax.random.key(3)

    eager = calc_barometer_readings(signal, samples, pressures)  # (eager noise draws compile slowly)
    np.testing.assert_array_equal(_readings(signal, samples, pressures), eager)
    batch = jnp.stack([pressures, 2 * pressures])
    mapped = jax.jit(jax.vmap(calc_barometer_readings, in_axes=(None, None, 0)))(signal, samples, batch)
    np.testing.assert_array_equal(mapped[1], _readings(signal, samples, batch[1]))

    # Straight-through quantisation: the gradient w.r.t. pressures is the gains, with noise.
    grad = jax.jit(jax.grad(lambda p: jnp.sum(weights * calc_barometer_readings(signal, samples, p, key=key))))(pressures)
    np.testing.assert_allclose(grad, weights * gains, rtol=1e-15)

    @jax.jit
    def loss(signal):
        return jnp.sum(weights * calc_barometer_readings(signal, samples, pressures, key=key, quantise=False))

    grad = jax.jit(jax.grad(loss))(signal)
    for name, field in [("gains", lambda s: s.gains), ("offsets", lambda s: s.offsets), ("drift_rates", lambda s: s.drift_rates)]:
        direction = jnp.asarray(rng.normal(size=3))
        step = 1e-3
        numeric = (float(loss(eqx.tree_at(field, signal, field(signal) + step * direction))) - float(loss(eqx.tree_at(field, signal, field(signal) - step * direction)))) / (2 * step)
        assert float(jnp.sum(field(grad) * direction)) == pytest.approx(numeric, rel=1e-6), name
    np.testing.assert_allclose(grad.gains, np.sum(weights * pressures, axis=0), rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [
        ({"gains": 0.0}, "gains must be positive"),
        ({"gains": [1.0, -1.0, 1.0]}, "gains must be positive"),
        ({"gains": [1.0, float("nan"), 1.0]}, "gains must be finite"),
        ({"noise_rms": -0.01}, "noise RMS must be a non-negative"),
        ({"noise_rms": float("nan")}, "noise RMS"),
        ({"rate_hz": 0.0}, "rate must be positive"),
        ({"rate_hz": -100.0}, "rate must be positive"),
        ({"offsets": [0.0, float("nan"), 0.0]}, "offsets must be finite"),
        ({"drift_rates": float("inf")}, "drift rates must be finite"),
    ],
    ids=["zero gain", "negative gain", "nan gain", "negative noise", "nan noise", "zero rate", "negative rate", "nan offset", "inf drift"],
)
def test_signal_rejects(part, kwargs, fragment):
    with pytest.raises(HydrotactError, match=fragment):
        make_barometer_signal(part, 3, **kwargs)


def test_signal_allows_zero_noise(part):
    signal = make_barometer_signal(part, 2, noise_rms=0.0)
    samples = jnp.linspace(0.0, 0.05, 6)
    noisy = _readings(signal, samples, jnp.zeros((6, 2)), key=jax.random.key(0))
    np.testing.assert_array_equal(noisy, _readings(signal, samples, jnp.zeros((6, 2))))


def test_signal_rejects_wrong_channel_count(part):
    with pytest.raises(HydrotactError, match="gains"):
        make_barometer_signal(part, 3, gains=[1.0, 2.0])
