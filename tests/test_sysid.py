"""System identification (hydrotact.sysid) on synthetic logs with a known material.

The logs (tests/sysid_synthetic.py) need no contact simulation: a press / hold /
release indentation history, unit responses ∝ depth^1.5, the exact hereditary
integral of the true Prony series, and the BMP388 signal model with channel gains,
offsets, 2 Pa white noise (a barometer cast in silicone) and the part's 0.016 Pa
quantisation; the reference force has 5 mN noise. Fits are shared through
module-scoped fixtures: each new problem shape compiles the solve once.
A new log of the same shapes reuses the compiled solve (checked by counting XLA
compilations).
"""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import pytest
from helpers import count_compilations
from sysid_synthetic import FullLogMaker

from hydrotact import HydrotactError
from hydrotact.data import BarometerLog, read_material
from hydrotact.sysid import (
    SOLVERS,
    BoundedLBFGSB,
    GaussNewtonArmijo,
    fit_auto,
    fit_parameters,
    fit_problem,
    fit_relaxation_curve,
    make_fit_problem,
    make_initial_guess,
    make_solver,
    solve_least_squares,
    solver_name,
)
from hydrotact.visco import make_prony

# E∞ and three well-separated terms (0.3, 3, 30 s).
TRUTH_3 = dict(long_term_modulus=6e5, moduli=[2.5e5, 1.5e5, 1.0e5], taus=[0.3, 3.0, 30.0])
TRUTH_2 = dict(long_term_modulus=6e5, moduli=[2.5e5, 1.5e5], taus=[0.5, 8.0])
COVERAGE_SEEDS = 50


def _prony(truth):
    return make_prony(truth["long_term_modulus"], truth["moduli"], truth["taus"])


def _material_estimates(result):
    """[E∞, E₁.., τ₁..] estimates (terms sorted by τ) of a FitResult."""
    return [result.long_term_modulus] + [m for m, _ in result.terms] + [t for _, t in result.terms]


def _material_truth(truth):
    return [truth["long_term_modulus"], *truth["moduli"], *truth["taus"]]


# --- shared logs and fits -------------------------------------------------------------


@pytest.fixture(scope="module")
def maker_3():
    """3 terms, 4 channels, 180 s at 50 Hz, holds up to 40 s (to see τ = 30 s)."""
    return FullLogMaker(_prony(TRUTH_3), duration=180.0, rate_hz=50.0, num_channels=4, trajectory_seed=3, holds=(2.0, 40.0))


@pytest.fixture(scope="module")
def problem_3(maker_3):
    return make_fit_problem([maker_3.make(0)], unit_responses=maker_3.unit_responses)


@pytest.fixture(scope="module")
def result_3(problem_3):
    return fit_problem(problem_3, 3)


@pytest.fixture(scope="module")
def maker_2():
    """2 terms, 4 channels, 90 s at 50 Hz: the coverage study's log."""
    return FullLogMaker(_prony(TRUTH_2), duration=90.0, rate_hz=50.0, num_channels=4, trajectory_seed=0)


@pytest.fixture(scope="module")
def problem_2(maker_2):
    return make_fit_problem([maker_2.make(0)], unit_responses=maker_2.unit_responses)


# --- 1. known-truth recovery ------------------------------------------------------------


def test_recovers_known_material(result_3):
    """Full mode, lm: E∞ within 1 %, each Eᵢ and τᵢ within 5 % (0.3 / 3 / 30 s)."""
    result = result_3
    assert result.converged
    assert 0.9 < result.reduced_chi_square < 1.1
    estimates = _material_estimates(result)
    truth = _material_truth(TRUTH_3)
    assert abs(estimates[0].value / truth[0] - 1.0) < 0.01, estimates[0]
    for estimate, value in zip(estimates[1:], truth[1:]):
        assert abs(estimate.value / value - 1.0) < 0.05, (estimate, value)


def test_logs_fit_jointly(maker_2, problem_2):
    """Two logs of one sensor (different trajectories, lengths and offsets, the same
    channel gains) fit jointly: one material, gains shared, offsets per log; the
    joint fit recovers the truth and is more certain than the first log alone."""
    other = FullLogMaker(_prony(TRUTH_2), duration=60.0, rate_hz=50.0, num_channels=4, trajectory_seed=11)
    other.gains = maker_2.gains  # the same barometers; offsets (ambient) differ per log
    logs = [maker_2.make(0), other.make(1)]
    joint = fit_problem(make_fit_problem(logs, unit_responses=maker_2.unit_responses + other.unit_responses), 2)
    alone = fit_problem(problem_2, 2)
    assert joint.converged and 0.9 < joint.reduced_chi_square < 1.1
    assert len(joint.gains) == 4 and [len(offsets) for offsets in joint.offsets()] == [4, 4]
    for offsets, maker in zip(joint.offsets(), (maker_2, other)):
        np.testing.assert_allclose([offsets[f"b{k}"].value - 101325.0 for k in range(4)], maker.offsets, atol=2.0)
    np.testing.assert_allclose([g.value for g in joint.gains.values()], maker_2.gains, rtol=0.01)
    for estimate, value, single in zip(_material_estimates(joint), _material_truth(TRUTH_2), _material_estimates(alone)):
        assert abs(estimate.value / value - 1.0) < 0.05, (estimate, value)
        assert estimate.std < single.std


def test_standard_errors_are_consistent(result_3, maker_3):
    """|estimate − truth| < 5σ for the material and the channel gains; σ > 0."""
    estimates = _material_estimates(result_3) + list(result_3.gains.values())
    truth = _material_truth(TRUTH_3) + list(maker_3.gains)
    assert len(result_3.gains) == 4
    for estimate, value in zip(estimates, truth):
        assert estimate.std > 0.0
        assert abs(estimate.value - value) < 5.0 * estimate.std, (estimate, value)
    # The covariance is symmetric, positive semidefinite, in log space.
    covariance = result_3.covariance
    np.testing.assert_allclose(covariance, covariance.T, rtol=0, atol=1e-12 * np.abs(covariance).max())
    assert np.linalg.eigvalsh(covariance).min() > -1e-12 * np.abs(covariance).max()


# --- 2. coverage of the 1σ intervals ------------------------------------------------------


def test_one_sigma_coverage(maker_2, problem_2):
    """Over 50 noise seeds (same trajectory and truth), the true value lies within
    the reported 1σ interval for 55-80 % of the fits, pooled over the material
    parameters E∞, E₁, E₂, τ₁, τ₂ (250 intervals; each parameter alone must stay
    within 50-90 %, a guard against one parameter's σ being far off that the pooled
    number could hide: 50 draws of a 68 % event fall outside 55-80 % too often to
    test parameters one by one).

    The 49 refits after the first compile nothing (checked).
    """
    truth = np.array(_material_truth(TRUTH_2))
    inside = []
    with count_compilations() as compilations:
        for seed in range(COVERAGE_SEEDS):
            problem = make_fit_problem([maker_2.make(seed)], unit_responses=maker_2.unit_responses)
            result = fit_problem(problem, 2)
            assert result.converged, seed
            estimates = _material_estimates(result)
            values = np.array([e.value for e in estimates])
            stds = np.array([e.std for e in estimates])
            inside.append(np.abs(values - truth) < stds)
            if seed == 0:
                first = len(compilations)
    inside = np.array(inside)
    per_parameter = inside.mean(axis=0)
    pooled = inside.mean()
    assert 0.55 <= pooled <= 0.80, (pooled, per_parameter)
    assert np.all((per_parameter >= 0.5) & (per_parameter <= 0.9)), per_parameter
    assert len(compilations) == first, f"{len(compilations) - first} compilations after the first seed"


def test_refit_of_same_shape_reuses_compiled_solve(maker_2, problem_2):
    """A new log of the same shapes, through the public calls, compiles nothing (a
    new solver object with the same settings as the default included)."""
    fit_problem(problem_2, 2)
    log = maker_2.make(1000)
    with count_compilations() as compilations:
        fit_problem(make_fit_problem([log], unit_responses=maker_2.unit_responses), 2, make_solver("lm"))
    assert not compilations, f"{len(compilations)} compilations"


# --- 3. solvers agree ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_problem():
    """2 terms, 2 channels, 40 s at 25 Hz."""
    maker = FullLogMaker(_prony(TRUTH_2), duration=40.0, rate_hz=25.0, num_channels=2, trajectory_seed=1, holds=(2.0, 15.0), gaps=(2.0, 8.0))
    return make_fit_problem([maker.make(0)], unit_responses=maker.unit_responses)


@pytest.fixture(scope="module")
def small_lm(small_problem):
    """The default solver (Levenberg–Marquardt, SOLVERS["lm"])."""
    return fit_problem(small_problem, 2)


@pytest.mark.parametrize(
    ("solver", "name"),
    [
        (GaussNewtonArmijo(rtol=1e-10, atol=1e-10), "gn"),
        (optx.Dogleg(rtol=1e-10, atol=1e-10), "dogleg"),
        (optx.BFGS(rtol=1e-10, atol=1e-10), "bfgs"),
        (BoundedLBFGSB(), "lbfgsb"),
    ],
    ids=["gn", "dogleg", "bfgs", "lbfgsb"],
)
def test_solvers_reach_the_same_minimum(small_problem, small_lm, solver, name):
    """Solver objects of each kind (least squares, minimiser, bounded L-BFGS-B) reach
    LM's minimum; those with the settings of a named choice report its name."""
    result = fit_problem(small_problem, 2, solver)
    assert small_lm.converged and result.converged
    assert small_lm.result == optx.RESULTS.successful and result.result == optx.RESULTS.successful
    assert (small_lm.solver_name, result.solver_name, result.solver) == ("lm", name, solver)
    assert abs(result.chi_square / small_lm.chi_square - 1.0) < 1e-6, (result.chi_square, small_lm.chi_square)
    for ours, reference in zip(_material_estimates(result), _material_estimates(small_lm)):
        assert abs(ours.value - reference.value) < 0.01 * reference.std


def test_capped_fit_reports_its_result(small_problem):
    """Capped at one step, fit_problem returns the max-steps code (throw=False, the
    default) or raises a HydrotactError with its message (throw=True)."""
    result = fit_problem(small_problem, 2, max_steps=1)
    assert result.result == optx.RESULTS.nonlinear_max_steps_reached and not result.converged and result.num_steps == 1
    with pytest.raises(HydrotactError) as error:
        fit_problem(small_problem, 2, max_steps=1, throw=True)
    _assert_one_line(error, "the lm solver failed after 1 steps", "maximum number of steps")


def _rosenbrock(x, args):
    """Rosenbrock's valley as residuals: the minimum 0 at (1, 1), far along a curved
    valley from the usual start (−1.2, 1)."""
    return jnp.stack([1.0 - x[0], 10.0 * (x[1] - x[0] ** 2)])


@pytest.mark.parametrize("name", list(SOLVERS))
def test_capped_solve_reports_its_result(name):
    """solve_least_squares capped at one step: throw=False returns the max-steps
    code; throw=True raises a HydrotactError with its message outside jit, and fails
    when the computation runs under jit. Uncapped, each solver reaches (1, 1)."""
    solver = make_solver(name)
    x0 = jnp.array([-1.2, 1.0])
    capped = solve_least_squares(_rosenbrock, x0, None, solver, max_steps=1, throw=False)
    assert capped.result == optx.RESULTS.nonlinear_max_steps_reached and not capped.converged and int(capped.num_steps) == 1
    with pytest.raises(HydrotactError, match=f"the {name} solver failed after 1 steps: The maximum number of steps"):
        solve_least_squares(_rosenbrock, x0, None, solver, max_steps=1, throw=True)
    with pytest.raises(eqx.EquinoxRuntimeError, match="maximum number of steps"):
        jax.block_until_ready(eqx.filter_jit(lambda x: solve_least_squares(_rosenbrock, x, None, solver, max_steps=1).value)(x0))
    solution = solve_least_squares(_rosenbrock, x0, None, solver)
    assert solution.converged
    np.testing.assert_allclose(solution.value, [1.0, 1.0], rtol=1e-6)


def test_lm_stops_at_a_kink_once_its_steps_are_tiny():
    """At a minimum on a discontinuity of the residuals (each jumps by 0.01 where it
    crosses 0), no step decreases the cost and optimistix's element-wise Cauchy test
    waits for ~1e-10 steps; our Levenberg-Marquardt stops once a retried step is
    below 1e-6 (1 + |y|): at the kink to that, in fewer steps, reported converged."""

    def jumps(y, args):
        offset = y - jnp.asarray([1.0, -2.0])
        return jnp.concatenate([offset + 0.01 * jnp.sign(offset), 0.1 * offset])

    x0 = jnp.asarray([3.0, 4.0])
    ours = solve_least_squares(jumps, x0, None, make_solver("lm"), throw=False)
    plain = solve_least_squares(jumps, x0, None, optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10, linear_solver=lx.Normal(lx.Cholesky())), throw=False)
    assert ours.converged and plain.converged
    np.testing.assert_allclose(ours.value, [1.0, -2.0], atol=3e-6)
    assert int(ours.num_steps) < 0.6 * int(plain.num_steps)


# --- 4. the number of terms ------------------------------------------------------------------


@pytest.mark.parametrize("case", ["two terms", "three terms"])
def test_fit_auto_picks_true_number_of_terms(case, request):
    problem, true_terms, max_terms = {"two terms": ("problem_2", 2, 3), "three terms": ("problem_3", 3, 4)}[case]
    problem = request.getfixturevalue(problem)
    result = fit_auto(problem, max_terms=max_terms)
    assert sorted(result.criteria) == list(range(max_terms + 1))
    assert all(np.isfinite(v) for v in result.criteria.values())
    assert result.layout.num_terms == true_terms, result.criteria
    assert min(result.criteria, key=result.criteria.get) == true_terms
    assert result.bic == result.criteria[true_terms]


# --- 5. implicit gradient through the solve ------------------------------------------------------


def test_fit_parameters_gradient_matches_refits():
    """d(v · x̂)/d(observed) by jax.grad through fit_parameters (implicit function
    theorem) matches central differences of refits at a few data entries; v is a
    fixed random direction over all parameters (material, gains, offsets)."""
    truth = make_prony(6e5, [3e5], [0.5])
    maker = FullLogMaker(truth, duration=6.0, rate_hz=50.0, num_channels=2, trajectory_seed=2, holds=(0.5, 1.5), gaps=(0.5, 1.0))
    problem = make_fit_problem([maker.make(0)], unit_responses=maker.unit_responses)
    assert problem.logs[0].observed.shape == (300, 3)
    layout, x0 = make_initial_guess(problem, 1)
    x0 = jnp.asarray(x0)
    direction = jnp.asarray(np.random.default_rng(0).normal(size=layout.size))
    solver = optx.LevenbergMarquardt(rtol=1e-14, atol=1e-14, linear_solver=lx.Normal(lx.Cholesky()))

    @eqx.filter_jit
    def fitted(observed):
        swapped = eqx.tree_at(lambda p: p.logs[0].observed, problem, observed)
        return direction @ fit_parameters(swapped, layout, x0, solver, max_steps=200)

    observed = problem.logs[0].observed
    gradient = np.asarray(jax.grad(fitted)(observed))
    assert gradient.shape == observed.shape and np.all(np.isfinite(gradient))
    # The entry of each column with the largest gradient, and two on a ramp. Steps of
    # one noise σ (2 Pa, 5 mN): the refits agree to ~1e-9 relative (LM's Cholesky on
    # the normal equations), so smaller steps drown in solver noise, while the
    # fitted parameters stay linear in the data to ~1e-9 over such steps.
    depth = maker.depth
    ramp = int(np.flatnonzero((depth > 0) & (depth < depth.max()))[0]) + 3
    entries = [(int(np.argmax(np.abs(gradient[:, column]))), column) for column in range(3)] + [(ramp, 1), (ramp + 100, 2)]
    for sample, column in entries:
        step = 2.0 if column < 2 else 5e-3
        bump = jnp.zeros_like(observed).at[sample, column].set(step)
        difference = (float(fitted(observed + bump)) - float(fitted(observed - bump))) / (2.0 * step)
        # atol: an entry of no consequence (gradient exactly 0) against the refits' noise (1e-14 measured)
        np.testing.assert_allclose(gradient[sample, column], difference, rtol=1e-4, atol=1e-9 * np.abs(gradient[:, column]).max(), err_msg=f"sample {sample} column {column}")


# --- 6. relaxation curves and pyvisco ----------------------------------------------------------------

RELAXATION_INF = 1e6
RELAXATION_TERMS = np.array([[3e5, 0.05], [2e5, 1.0], [1e5, 20.0]])  # (Eᵢ Pa, τᵢ s)


def _relaxation_curve():
    times = np.geomspace(1e-3, 1e3, 200)
    moduli, taus = RELAXATION_TERMS.T
    return times, RELAXATION_INF + np.exp(-times[:, None] / taus[None, :]) @ moduli


def _relaxation_truth():
    return np.concatenate([[RELAXATION_INF], RELAXATION_TERMS[:, 0], RELAXATION_TERMS[:, 1]])


def test_relaxation_curve_exact_on_noiseless_data():
    times, modulus = _relaxation_curve()
    fit = fit_relaxation_curve(times, modulus, 3)
    assert fit.converged
    values = np.array([fit.long_term_modulus.value] + [m.value for m, _ in fit.terms] + [t.value for _, t in fit.terms])
    np.testing.assert_allclose(values, _relaxation_truth(), rtol=1e-8)
    assert fit.residual_rms < 1e-8 * RELAXATION_INF


def test_relaxation_curve_no_worse_than_pyvisco():
    """Same curve, 0.1 % relative noise, three terms: our largest and RMS relative
    parameter error and our RMS residual are no worse than pyvisco's."""
    pytest.importorskip("pyvisco")
    from pyvisco_reference import fit_prony_pyvisco

    times, clean = _relaxation_curve()
    noisy = clean * (1.0 + 1e-3 * np.random.default_rng(0).standard_normal(times.size))
    truth = _relaxation_truth()
    fit = fit_relaxation_curve(times, noisy, 3)
    ours = np.array([fit.long_term_modulus.value] + [m.value for m, _ in fit.terms] + [t.value for _, t in fit.terms])
    reference = fit_prony_pyvisco(times, noisy, 3)
    theirs = np.concatenate([[reference["long_term_modulus"]], reference["moduli"], reference["taus"]])
    our_errors, their_errors = np.abs(ours / truth - 1.0), np.abs(theirs / truth - 1.0)
    assert our_errors.max() <= their_errors.max(), (our_errors, their_errors)
    assert np.sqrt(np.mean(our_errors**2)) <= np.sqrt(np.mean(their_errors**2)), (our_errors, their_errors)
    assert fit.residual_rms <= reference["residual_rms"], (fit.residual_rms, reference["residual_rms"])
    # Our standard errors cover the truth (0.1 % noise: errors of ~1e-3 relative).
    stds = np.array([fit.long_term_modulus.std] + [m.std for m, _ in fit.terms] + [t.std for _, t in fit.terms])
    assert np.all(np.abs(ours - truth) < 5.0 * stds), ((ours - truth) / stds)


# --- 7. bad input ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_maker():
    return FullLogMaker(_prony(TRUTH_2), duration=6.0, rate_hz=20.0, num_channels=2, trajectory_seed=4, holds=(0.5, 1.5), gaps=(0.5, 1.0))


def _assert_one_line(error, *fragments):
    message = str(error.value)
    assert "\n" not in message, message
    for fragment in fragments:
        assert fragment in message, (fragment, message)


def test_too_few_samples(tiny_maker):
    log = tiny_maker.make(0)
    columns = {k: v[:5] for k, v in log.columns.items()}
    with pytest.raises(HydrotactError) as error:
        make_fit_problem([BarometerLog(log.metadata, columns)], unit_responses=[tuple(a[:5] for a in tiny_maker.unit_responses[0])])
    _assert_one_line(error, "5 samples", "at least 8")


def test_unit_responses_of_wrong_shape(tiny_maker):
    unit, force = tiny_maker.unit_responses[0]
    log = tiny_maker.make(0)
    for responses in [(unit[:, :1], force), (unit, force[:, :2]), (unit[:-1], force[:-1])]:
        with pytest.raises(HydrotactError) as error:
            make_fit_problem([log], unit_responses=[responses])
        _assert_one_line(error, "unit responses", "do not match")


def test_no_logs():
    with pytest.raises(HydrotactError) as error:
        make_fit_problem([])
    _assert_one_line(error, "no logs")


@pytest.mark.parametrize(
    ("solver", "num_terms", "fragments"),
    [("lm", 1, ("got str", "make_solver('lm')", "lbfgsb")), (object(), 1, ("got object",)), (None, -1, ("0 or more", "-1"))],
    ids=["name", "object", "terms"],
)
def test_fit_problem_bad_arguments(tiny_maker, solver, num_terms, fragments):
    problem = make_fit_problem([tiny_maker.make(0)], unit_responses=tiny_maker.unit_responses)
    with pytest.raises(HydrotactError) as error:
        fit_problem(problem, num_terms, solver)
    _assert_one_line(error, *fragments)


def test_make_solver():
    """The named choices make the solvers they name; an unknown name lists them."""
    for name in SOLVERS:
        assert solver_name(make_solver(name)) == name
    assert solver_name(optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)) == "LevenbergMarquardt"
    with pytest.raises(HydrotactError) as error:
        make_solver("newton")
    _assert_one_line(error, "unknown solver 'newton'", "lm, gn, dogleg, bfgs, lbfgsb")


@pytest.mark.parametrize(("times", "modulus", "fragment"), [([0.0, 1.0, 2.0], [3.0, 2.0, 1.0], "at least 4"), ([0.0, 1.0, 2.0, 3.0], [3.0, 2.0, 0.0, 1.0], "positive moduli")])
def test_relaxation_curve_bad_input(times, modulus, fragment):
    with pytest.raises(HydrotactError) as error:
        fit_relaxation_curve(times, modulus, 1)
    _assert_one_line(error, fragment)


# --- 8. outputs ---------------------------------------------------------------------------------------------

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _check_outputs(result, out_dir):
    from hydrotact.sysid import write_fit_outputs
    from hydrotact.viz import plot_fit

    report = write_fit_outputs(result, out_dir, plot=plot_fit)
    material = read_material(out_dir / "material.json")
    saved = json.loads((out_dir / "report.json").read_text())
    assert saved["files"] == report["files"]
    for name in ("traces.png", "residuals.png", "relaxation.png"):
        data = (out_dir / name).read_bytes()
        assert data.startswith(PNG_SIGNATURE) and len(data) > 1000, name
    assert material["long_term_modulus_Pa"]["value"] == pytest.approx(result.long_term_modulus.value, rel=1e-12)
    for term, (modulus, tau) in zip(material["prony_terms"], result.terms, strict=True):
        assert term["modulus_Pa"]["value"] == pytest.approx(modulus.value, rel=1e-12)
        assert term["tau_s"]["value"] == pytest.approx(tau.value, rel=1e-12)
        assert term["tau_s"]["std"] == pytest.approx(tau.std, rel=1e-12)
    assert saved["num_terms"] == result.layout.num_terms
    assert saved["reduced_chi_square"] == pytest.approx(result.reduced_chi_square)
    return material, saved


def test_write_fit_outputs_full(result_3, tmp_path):
    material, report = _check_outputs(result_3, tmp_path)
    assert "modulus_scale" not in material
    assert material["long_term_modulus_Pa"]["std"] > 0.0
    assert [channel["name"] for channel in material["channels"]] == [f"b{k}" for k in range(4)]
    assert all("gain" in channel for channel in material["channels"])
    covariance = material["covariance"]
    assert covariance["space"] == "log" and len(covariance["parameters"]) == 7
    assert report["mode"] == "full" and report["converged"]
    assert report["solver"] == material["provenance"]["solver"] == "lm"  # the name, as before solvers were objects



def test_a_parameter_without_a_finite_standard_error_is_written_without_one(small_lm, capsys):
    """A fit whose covariance has a direction the logs do not constrain (NaN or inf:
    a term driven to nothing, 0 x inf) wrote nothing before and ended with
    "prony_terms[0].modulus_Pa.std: must be a finite number, got nan" (issue 49): the
    material now leaves that std and the covariance out, and the report says the term
    is not identified, with null, not NaN, in its JSON."""
    import dataclasses
    import json

    from hydrotact.sysid import make_report
    from hydrotact.sysid._report import make_fit_material

    k = small_lm.names.index("log_modulus_1")
    covariance = small_lm.covariance.copy()
    covariance[k, :] = covariance[:, k] = np.nan
    broken = dataclasses.replace(small_lm, covariance=covariance)
    material = make_fit_material(broken)  # schema-checked inside
    assert "covariance" not in material
    stds = [("std" in term["modulus_Pa"], "std" in term["tau_s"]) for term in material["prony_terms"]]
    assert stds.count((False, True)) == 1 and stds.count((True, True)) == len(stds) - 1
    report = json.loads(json.dumps(make_report(broken), allow_nan=False))
    moduli = [term["modulus_Pa"] for term in report["prony_terms"]]
    unconstrained = [m for m in moduli if m["std"] is None]
    assert len(unconstrained) == 1 and not unconstrained[0]["identified"] and "no finite standard error" in unconstrained[0]["note"]
    assert "std" in material["long_term_modulus_Pa"]
    from hydrotact.cli.fit import print_fit_table

    print_fit_table(report)  # the command line's table: no format of a missing error
    printed = capsys.readouterr().out
    assert "NOT IDENTIFIED" in printed and "no finite error" in printed  # E1, and E0 whose error sums E1's
