"""pyvisco's Prony-series fit of a time-domain relaxation curve, as a reference.

pyvisco (Martin Springer, PyPI ``pyvisco``; a ``test`` extra) fits a Prony series
E(t) = E_inf + sum_i E_i exp(-t / tau_i) to a relaxation master curve. It is written
around a Voila GUI; this module drives its library functions directly, the same way
its GUI does, with no figures and no printing:

1. ``load.user_master``: the curve goes in as an in-memory CSV with the two-row
   header ``t,E_relax`` / ``s,Pa`` (domain ``'time'``, modulus ``'E'``, RefT 0 C:
   the curve is taken as a master curve at one reference temperature; the unit only
   labels plots, the fit itself works on E / E_0).
2. ``master.smooth(win=1)``: adds the ``E_relax_filt`` column the fit reads
   (window 1 = no filtering).
3. ``prony.discretize`` + ``prony.fit`` / ``prony.fit_time``:

   - ``num_terms=None``, pyvisco's default (initial) fit: ``window='round'``, one
     tau per decade at fixed powers of ten spanning
     [10**ceil(log10(t_min / 2 pi)), 10**floor(log10(t_max / 2 pi))] (pyvisco maps
     a sample time t to tau = 1 / omega = t / (2 pi)); only the alpha_i are fitted
     (L-BFGS-B, 0 <= alpha_i <= 1), the taus stay on the grid.
   - ``num_terms=N``, pyvisco's term-reduction step for N terms: exactly what
     ``opt.nprony`` computes for its entry N, i.e. ``discretize(window='min',
     nprony=N)`` (N taus log-spaced strictly inside [t_min, t_max] / 2 pi) then
     ``fit_time(opt=True)`` (alpha_i fitted with taus fixed, then alpha_i and tau_i
     together with L-BFGS-B, taus bounded to [t_min, t_max] / 2 pi). It is called
     for N directly rather than through ``opt.nprony``, which only offers
     N = n0 - 1 down to 3 (n0 = terms of the default fit, odd N above 20 skipped)
     and fits every one of them; for the N it does offer the result is identical
     (same calls on the same inputs, checked in ``__main__``).
   - ``num_terms='auto'``: the default fit, then ``opt.nprony(window='min',
     opt=1.5)`` and its suggested N_opt (the N whose residual is nearest 1.5 x the
     smallest one), as the GUI suggests.

pyvisco's model and its assumptions (they bias its answer, not ours):

- E_0 (instantaneous modulus) is not fitted: it is the modulus of the earliest
  sample, and E(t) = E_0 (1 - sum alpha_i + sum alpha_i exp(-t / tau_i)), so
  E_inf = E_0 (1 - sum alpha_i) and E_i = E_0 alpha_i. A curve that has not reached
  its glassy plateau at t_min (or a noisy first sample) biases every term.
- Moduli are non-negative (0 <= alpha_i, sum alpha_i <= 1; rescaled to 1 if above),
  i.e. a monotonically relaxing curve; taus lie within [t_min, t_max] / 2 pi.
- The least-squares objective is unweighted on E / E_0 over the samples as given,
  so log-spaced samples (as from a master curve) are what it expects.
- Terms may come back with alpha_i = 0; they are returned as they are, so
  ``len(taus) == num_terms`` when num_terms is an int.
"""

import contextlib
import io
import sys
import time
import warnings

import numpy as np


def _import_pyvisco():
    """Import pyvisco headless (Agg unless pyplot is already up), warnings suppressed."""
    if "matplotlib.pyplot" not in sys.modules:
        import matplotlib

        matplotlib.use("Agg")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from pyvisco import load, master, opt, prony
    return load, master, opt, prony


def _csv(times, modulus):
    rows = "".join(f"{float(t)!r},{float(e)!r}\n" for t, e in zip(times, modulus, strict=True))
    return ("t,E_relax\ns,Pa\n" + rows).encode()


def prony_relaxation(times, long_term_modulus, moduli, taus):
    """E(t) = E_inf + sum_i E_i exp(-t / tau_i), evaluated at `times`."""
    t = np.asarray(times, dtype=float)
    moduli = np.asarray(moduli, dtype=float)
    taus = np.asarray(taus, dtype=float)
    return long_term_modulus + np.exp(-t[:, None] / taus[None, :]) @ moduli


def fit_prony_pyvisco(times, modulus, num_terms=None) -> dict:
    """Fit E(t) = E_inf + sum_i E_i exp(-t / tau_i) with pyvisco.

    `times` in s (> 0), `modulus` in Pa, 1-D and of equal length (sorted by time
    here). `num_terms`: None for pyvisco's default fit (one term per decade, taus
    fixed), an int N for pyvisco's N-term reduction step (taus optimised), or
    'auto' for the N that pyvisco's `opt.nprony` suggests (see the module notes).

    Returns a dict: `long_term_modulus` (Pa), `moduli` (Pa) and `taus` (s) as
    arrays sorted by ascending tau, `residual_rms` (RMS of modulus - fit over the
    given samples, Pa), `seconds` (wall time of pyvisco's whole pipeline: loading,
    discretisation, fit and any term reduction; not the import), and also
    `instantaneous_modulus` (pyvisco's E_0, the earliest sample), `num_terms`,
    `pyvisco_err` (pyvisco's own least-squares residual, on E / E_0) and `method`.
    Deterministic; prints nothing, draws nothing, raises no warnings.
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(modulus, dtype=float)
    if t.ndim != 1 or t.shape != e.shape or t.size < 2:
        raise ValueError("times and modulus must be 1-D arrays of equal length >= 2")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(e)) and np.all(t > 0)):
        raise ValueError("times must be finite and > 0, modulus finite")
    if num_terms is not None and num_terms != "auto":
        if int(num_terms) != num_terms or num_terms < 1:
            raise ValueError("num_terms must be None, 'auto' or a positive integer")
        num_terms = int(num_terms)
    order = np.argsort(t, kind="stable")
    t, e = t[order], e[order]

    load, master, opt, prony = _import_pyvisco()
    data = _csv(t, e)
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        start = time.perf_counter()
        df_master, _units = load.user_master(data, "time", 0.0, "E")
        df_master = master.smooth(df_master, 1)
        if isinstance(num_terms, int):
            df_dis = prony.discretize(df_master, "min", num_terms)
            result = prony.fit_time(df_dis, df_master, opt=True)
            method = f"discretize(window='min', nprony={num_terms}) + fit_time(opt=True)"
        else:
            df_dis = prony.discretize(df_master, "round", 0)
            result, _ = prony.fit(df_dis, df_master, opt=False)
            method = "discretize(window='round') + fit(opt=False): one fixed tau per decade"
            if num_terms == "auto":
                dict_prony, n_opt, _err = opt.nprony(df_master, result, window="min", opt=1.5)
                result = dict_prony[n_opt]
                method += f"; opt.nprony(window='min', opt=1.5) -> N_opt = {n_opt}"
        seconds = time.perf_counter() - start

        terms = result["df_terms"]
        taus = np.asarray(terms["tau_i"], dtype=float)
        alphas = np.asarray(terms["alpha_i"], dtype=float)
        e_0 = float(result["E_0"])
        err = float(result["err"])

    by_tau = np.argsort(taus, kind="stable")
    taus, alphas = taus[by_tau], alphas[by_tau]
    moduli = e_0 * alphas
    long_term = e_0 * (1.0 - float(np.sum(alphas)))
    fitted = prony_relaxation(t, long_term, moduli, taus)
    return {
        "long_term_modulus": long_term,
        "moduli": moduli,
        "taus": taus,
        "residual_rms": float(np.sqrt(np.mean((e - fitted) ** 2))),
        "seconds": seconds,
        "instantaneous_modulus": e_0,
        "num_terms": int(taus.size),
        "pyvisco_err": err,
        "method": method,
    }


if __name__ == "__main__":
    # Synthetic check: E_inf = 1 MPa, three terms, 200 log-spaced samples, 1 ms .. 1 ks.
    E_INF = 1e6
    TRUE = np.array([[3e5, 0.05], [2e5, 1.0], [1e5, 20.0]])
    t = np.geomspace(1e-3, 1e3, 200)
    clean = prony_relaxation(t, E_INF, TRUE[:, 0], TRUE[:, 1])
    noisy = clean * (1.0 + 1e-3 * np.random.default_rng(0).standard_normal(t.size))

    def report(label, fit, truth):
        print(f"\n{label}: {fit['method']}")
        print(f"  E_inf = {fit['long_term_modulus']:.6g} Pa  (rel err {fit['long_term_modulus'] / E_INF - 1:+.2e})")
        for modulus, tau in zip(fit["moduli"], fit["taus"], strict=True):
            print(f"  E_i = {modulus:12.6g} Pa  tau_i = {tau:10.5g} s")
        if fit["num_terms"] == len(TRUE):
            rel_e = fit["moduli"] / TRUE[:, 0] - 1
            rel_t = fit["taus"] / TRUE[:, 1] - 1
            print("  rel err E_i:  " + "  ".join(f"{x:+.2e}" for x in rel_e))
            print("  rel err tau_i:" + "  ".join(f"{x:+.2e}" for x in rel_t))
        model = prony_relaxation(t, fit["long_term_modulus"], fit["moduli"], fit["taus"])
        rms_truth = np.sqrt(np.mean((truth - model) ** 2))
        print(f"  residual RMS vs data {fit['residual_rms']:.4g} Pa, vs noiseless truth {rms_truth:.4g} Pa")
        e_0, e_0_true = fit["instantaneous_modulus"], E_INF + TRUE[:, 0].sum()
        print(f"  E_0 = {e_0:.6g} Pa (true {e_0_true:.6g}), {fit['seconds'] * 1e3:.1f} ms")

    for name, data in (("noiseless", clean), ("0.1 % noise", noisy)):
        for n in (None, 3, "auto"):
            report(f"{name}, num_terms={n}", fit_prony_pyvisco(t, data, n), clean)

    # Determinism, and the direct N-term call equals opt.nprony's entry for N.
    a, b = fit_prony_pyvisco(t, noisy, 3), fit_prony_pyvisco(t, noisy, 3)
    assert all(np.array_equal(a[k], b[k]) for k in ("long_term_modulus", "moduli", "taus"))
    load, master, opt, prony = _import_pyvisco()
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        df_master = master.smooth(load.user_master(_csv(t, noisy), "time", 0.0, "E")[0], 1)
        initial, _ = prony.fit(prony.discretize(df_master, "round", 0), df_master)
        dict_prony, _, _ = opt.nprony(df_master, initial, window="min", opt=1.5)
    via_nprony = np.sort(np.asarray(dict_prony[3]["df_terms"]["tau_i"], dtype=float))
    assert np.array_equal(via_nprony, a["taus"]), (via_nprony, a["taus"])
    print(f"\ndeterministic; N=3 matches opt.nprony (which offers N = {sorted(dict_prony)})")
