"""The onset scan of the lumped press model (pure, but for the host loop over the
sites in :func:`scan_site_onsets`): after a solve, each site's presses' onsets are
moved together over ONSET_SCAN, each shift judged by the χ² with that site's law and
the baselines refitted and the rest held, the best few by the whole projection
(:func:`projection_at`). :mod:`._press_solve` re-solves from the scan's best. The
model itself is :mod:`._lumped`'s."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._lumped import ONSET_HALF_RANGE, PressLayout, calc_projection
from ._press_projection import ACTIVE_PASSES, baseline_inverses, solve_linear, solve_scaled
from ._press_windows import calc_depths, calc_site_bases, window_decay

# A site's onsets and its law nearly trade: shifting all of a site's presses' onsets
# by ε and reshaping its law mimics the readings except at a press's first samples of
# contact, so the solver can end where every press at a site starts early (or late)
# by the same amount. On test_lumped's model log (3 sites, 2 presses each, 2 Pa
# noise), Levenberg-Marquardt from starts within ±80 µm of the truth ended with site
# 0's presses both 152 µm early: a χ² of 3151.9 against 3108.2 from the true onsets,
# a reduced χ² of 0.99 that no threshold on the fit's quality sees. A scan of each
# site's common onset shift, the rest held, finds the true basin (3114.9 at +150 µm
# before any re-solve).
with jax.enable_x64(True):  # the same float64 shifts however the importer has set JAX's precision
    ONSET_SCAN = tuple(float(v) for v in jnp.linspace(-300e-6, 300e-6, 25))  # m, the shifts tried (25 µm apart)


def _shift_site(layout: PressLayout, x, args, site, offset):
    """x with every press at `site` (in every log) moved by `offset` in onset, and
    whether the moved onsets stay inside their ranges."""
    datas, onset_starts, _ = args
    first, feasible = 2 * layout.num_terms, jnp.asarray(True)
    for count, start, data in zip(layout.num_presses, onset_starts, datas):
        onsets = start + ONSET_HALF_RANGE * jnp.tanh(x[first : first + count])
        moved = (jnp.where(data.press_site == site, onsets + offset, onsets) - start) / ONSET_HALF_RANGE
        feasible &= jnp.all(jnp.abs(moved) < 0.999)
        x = x.at[first : first + count].set(jnp.arctanh(jnp.clip(moved, -0.999, 0.999)))
        first += count
    return x, feasible


def _site_law_cost(own, others, datas, actives, contact, site):
    """The solver's χ² with one site's law and every baseline refitted, the other
    sites' laws held: per log the site's bases `own` (T, J), the other sites'
    elastic sum `others` (T, C) and the contact (T,); each channel's elastic part on
    where `actives` says (per log (T, C)), then, ACTIVE_PASSES times, where the
    refitted sum pushes (as :func:`find_actives` does). Solves of the baselines' and
    J columns per channel instead of every site's."""
    for last in [False] * ACTIVE_PASSES + [True]:
        held = [eqx.tree_at(lambda d: (d.observed, d.responds), data, (data.observed - a * o, data.responds[:, site, None])) for data, a, o in zip(datas, actives, others)]
        _, law, residuals = solve_linear([b[:, None, :] for b in own], held, actives, contact)
        if not last:
            actives = [c[:, None] & (o + b @ law[:, 0, :].T > 0.0) for c, o, b in zip(contact, others, own)]
    return sum(jnp.sum(r**2) for r in residuals)


def _site_law_cost_projected(own, others, datas, actives, contact, site, baselines, inverses):
    """:func:`_site_law_cost` where every log's baseline is learned over the whole log
    (drift_from "all"): the baseline projected out (its Gram matrix' inverse per log
    `inverses`, :func:`baseline_inverses`, the same for every shift) instead of
    refitted with the law, so each pass solves J unknowns per channel and never forms
    the (C, T, D) baseline columns; the readings less the baselines at x
    (`baselines`, in the baseline's span, so the result is the same) keep the sums
    of squares small. The same χ² to rounding (test_lumped)."""
    for last in [False] * ACTIVE_PASSES + [True]:
        normal, rhs, pieces = 0.0, 0.0, []
        for data, active, other, basis, baseline, inverse in zip(datas, actives, others, own, baselines, inverses):
            weights = data.weights.T  # (C, T)
            columns = basis[None, :, :] * (active.T * weights * data.responds[:, site, None])[:, :, None]  # (C, T, J)
            target = (data.observed - baseline - active * other).T * weights  # (C, T)
            cross = jnp.einsum("td,ctj->cdj", data.baseline, columns * weights[:, :, None])  # (C, D, J): weighted baseline columns' with the law's
            projected = jnp.einsum("td,ct->cd", data.baseline, target * weights)  # (C, D)
            normal = normal + jnp.einsum("ctj,ctk->cjk", columns, columns) - jnp.einsum("cdj,cde,cek->cjk", cross, inverse, cross)
            rhs = rhs + jnp.einsum("ctj,ct->cj", columns, target) - jnp.einsum("cdj,cde,ce->cj", cross, inverse, projected)
            pieces.append((columns, target, cross, projected, inverse))
        law = solve_scaled(normal, rhs)  # (C, J)
        if not last:
            actives = [c[:, None] & (o + b @ law.T > 0.0) for c, o, b in zip(contact, others, own)]
    cost = 0.0
    for columns, target, cross, projected, inverse in pieces:
        residual = target - jnp.einsum("ctj,cj->ct", columns, law)
        left = projected - jnp.einsum("cdj,cj->cd", cross, law)  # the weighted baseline columns against the residual
        cost = cost + jnp.sum(residual**2) - jnp.einsum("cd,cde,ce->", left, inverse, left)
    return cost


@eqx.filter_jit
def _site_scan(layout: PressLayout, x, args, site, offsets, projection, held, project_baselines=True):
    """Each shift's χ² with the site's law and the baselines refitted to it, the other
    sites' laws held at the projection's at x (`projection`: :func:`projection_at`'s
    amplitudes, actives, contact, baselines and bases; `held`: :func:`scan_constants`,
    what no shift changes), each channel's elastic part on where
    it was at x and, where a shift brings a sample into contact, where the laws at x
    push, to start the active-set passes (started from the whole contact instead,
    with the other sites held, they end thousands in χ² above the projection's at
    the same onsets on a 20-site log). ∞ where an onset would leave its range.
    Baselines learned over the whole log are projected out rather than refitted
    (:func:`_site_law_cost_projected`: the same χ², a scan 2-3x faster), unless
    `project_baselines` is False."""
    datas, onset_starts, lags = args
    amplitudes, actives_x, contact_x, baselines_x, bases_x = projection
    decays, inverses = held
    shape = layout.unpack(x, onset_starts, lags)[0]
    projected = project_baselines and inverses is not None
    # A shift moves this site's bases alone: the other sites' elastic sums and the
    # windows' decay (the τ's) are those at x.
    others = [jnp.einsum("tsj,csj->tc", bases, amplitudes) - bases[:, site, :] @ amplitudes[:, site, :].T for bases in bases_x]

    def shifted(offset):
        moved, feasible = _shift_site(layout, x, args, site, offset)
        _, onsets, moved_lags = layout.unpack(moved, onset_starts, lags)
        own, actives, contact = [], [], []
        for data, onset, lag, active, touching, other, decay in zip(datas, onsets, moved_lags, actives_x, contact_x, others, decays):
            depths = calc_depths(data, onset, lag)
            own.append(calc_site_bases(shape, depths, data, site, decay))
            pushes = other + own[-1] @ amplitudes[:, site, :].T > 0.0
            contact.append(depths > 0.0)
            actives.append(contact[-1][:, None] & jnp.where(touching[:, None], active, pushes))
        if projected:
            cost = _site_law_cost_projected(own, others, datas, actives, contact, site, baselines_x, inverses)
        else:
            cost = _site_law_cost(own, others, datas, actives, contact, site)
        return jnp.where(feasible, cost, jnp.inf)

    return jax.lax.map(shifted, offsets)


@eqx.filter_jit
def projection_at(layout: PressLayout, x, args):
    """(the solver's χ², (the amplitudes, the actives per log, the contact per log,
    the fitted baselines per log (T, C), the bases per log (T, S, J))) at x:
    :func:`calc_press_residuals`, with what the scan holds."""
    datas, onset_starts, lags = args
    residuals, drifts, amplitudes, actives, contact, bases = calc_projection(*layout.unpack(x, onset_starts, lags), datas)
    baselines = [data.baseline @ coefficients.T for data, coefficients in zip(datas, drifts)]  # (T, C) per log
    return sum(jnp.sum(r**2) for r in residuals), (amplitudes, actives, contact, baselines, bases)


@eqx.filter_jit
def scan_constants(layout: PressLayout, x, args):
    """What no onset shift changes, computed once per scan: per log the windows' decay
    (:func:`window_decay`, for x's τ) and, where every baseline is learned over its
    whole log, the inverses that project it out (:func:`baseline_inverses`; else
    None)."""
    datas = args[0]
    taus = layout.unpack(x, *args[1:])[0].taus
    decays = [window_decay(taus, data)[0] for data in datas]
    return decays, (baseline_inverses(datas) if all(data.drift_from != "unloaded" for data in datas) else None)


def scan_site_onsets(layout: PressLayout, x, args, offsets=ONSET_SCAN, scale=1.0):
    """One pass over the sites: each site's onsets moved together by the shift of
    `offsets` that lowers the solver's χ² most, the others held (the earlier sites
    at their new shifts). Returns (x, its χ²);
    x unchanged where no shift lowers it. A shift is judged only where the scan
    lowers the χ² significantly (:data:`SCAN_MIN_GAIN` times `scale`, the χ² per
    residual where above 1).
    A shift at one site changes that site's bases alone, so each shift is judged by
    the χ² with that site's law and the baselines refitted and the rest held
    (:func:`_site_scan`: J unknowns per channel, the baselines projected out, instead
    of S J more), and the scan's lowest minima (:func:`_lowest_minima`) by the whole
    projection: the best kept where it lowers the solver's χ². On the full-size
    stand-in (20 sites, 25 shifts) this is at most 3 whole projections per site
    instead of 25. The shifts run one at a time (lax.map: a long log's bases are
    not held 25 times over)."""
    offsets = jnp.asarray(offsets, x.dtype)
    unmoved = int(jnp.argmin(jnp.abs(offsets)))
    at_x, projection = projection_at(layout, x, args)  # what the scan holds, with the solver's χ² at x
    held = scan_constants(layout, x, args)  # a shift moves no τ
    best = float(at_x)
    for site in range(args[0][0].num_sites):
        costs = np.asarray(_site_scan(layout, x, args, jnp.asarray(site), offsets, projection, held))
        site_best = (best, x, projection)
        for index in _lowest_minima(costs, unmoved, SCAN_MIN_GAIN * scale):
            moved = _shift_site(layout, x, args, jnp.asarray(site), offsets[index])[0]
            moved_cost, moved_projection = projection_at(layout, moved, args)
            if float(moved_cost) < site_best[0]:
                site_best = (float(moved_cost), moved, moved_projection)
        best, x, projection = site_best
    return x, best


SCAN_CANDIDATES = 3  # a site's shifts judged by the whole projection: its scan's lowest local minima
# A shift the scan finds is judged by the whole projection only where it lowers the
# site's χ² by more than χ²(1)'s 5 % point (a site's common shift is one parameter
# more): on the three full-size stand-ins, 22 of a scan's 31 candidates lowered it by
# 0-3 (a move inside the onsets' own errors, each projection 0.25 s of a 63 s cold
# fit), where the trap the scan is for lowers it by 37 (test_lumped) and a real onset
# error by hundreds.
SCAN_MIN_GAIN = 3.84


def _lowest_minima(costs, unmoved, min_gain=0.0):
    """Indices of the SCAN_CANDIDATES lowest local minima of a site's scan `costs`
    more than `min_gain` below the unmoved shift's. The reduced χ² is not the projection's (its active
    set is refined from the one at x, the projection's starts from the whole contact
    each time): on test_lumped's trap it ties a shift 50 µm the wrong way with the
    true one, 150 µm the right way, which the projection alone tells apart."""
    padded = np.concatenate([[np.inf], costs, [np.inf]])
    minima = [k for k in range(len(costs)) if padded[k + 1] <= padded[k] and padded[k + 1] <= padded[k + 2] and costs[k] < costs[unmoved] - min_gain]
    return sorted(minima, key=lambda k: costs[k])[:SCAN_CANDIDATES]
