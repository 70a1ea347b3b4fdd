"""One climb of a layout design, and the scoring it rests on (host driver with jitted
kernels): the score of a layout over linearised contacts, its gradients in the ports
(mm), raw axes and field sizes, and Adam with projection onto the feasible layouts
from one start. :func:`hydrotact.design.design_layout` runs it from every start."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._buffers import run_growing
from ..taxel import TaxelCapacity
from ._feasible import FeasibleRegion
from ._objective import (
    DesignObjective,
    _balance_neighbour_errors,
    calc_design_score,
    calc_layout_information,
    calc_layout_readings,
    calc_localisation_bounds,
    calc_neighbour_errors,
    calc_neighbour_score,
)

POSITION_UNIT = 1e-3
"""Ports (and disk radii) are optimised in millimetres."""


START_TAXEL_CAPACITY = TaxelCapacity(pairs=8192, pieces=8192)
"""The taxel buffers a design starts with (sphere8's eight cones need ~5000 pairs)."""
MIN_FIELD_SIZE = 1e-4
"""The smallest designed field size: a disk radius of 0.1 mm, a half-angle of 0.1 mrad
(a designed size is projected onto [MIN_FIELD_SIZE, MAX_HALF_ANGLE] for a cone)."""
MAX_HALF_ANGLE = np.radians(85.0)
"""The widest designed cone (a half-angle of 90 deg would see only the board's plane)."""


class _Scored(eqx.Module):
    score: jax.Array
    gradients: tuple
    did_overflow: jax.Array
    needed: jax.Array


def _size_units(template):
    """Each field size's unit in the optimiser: rad for a cone, mm for a disk."""
    return jnp.where(template.is_cone, 1.0, POSITION_UNIT)


def _layout(template, positions_mm, axes, sizes):
    return eqx.tree_at(
        lambda layout: (layout.positions_S, layout.axes_S, layout.field_sizes), template,
        (positions_mm * POSITION_UNIT, axes / jnp.linalg.norm(axes, axis=1, keepdims=True), sizes * _size_units(template)),
    )


def _take(contacts, indices):
    """The contacts `indices` (a traced index array): the tangents of integer fields
    (float0, numpy) are made anew in the new shape."""

    def take(a):
        if not getattr(a, "ndim", 0):
            return a
        if a.dtype == jax.dtypes.float0:
            return np.zeros((indices.shape[0], *a.shape[1:]), dtype=jax.dtypes.float0)
        return jnp.asarray(a)[indices]

    return jax.tree_util.tree_map(take, contacts)


def _make_scorer(contacts, targets, noise, prior, objective, num_rays, balance=1.0):
    """(capacity, template, params, indices) -> _Scored: the score over the contacts
    `indices` and its gradients in the params (positions in mm, raw axes, field
    sizes), jitted once per capacity."""
    cache = {}

    def scorer(capacity, template, params, indices):
        if capacity not in cache:

            def score(params, template, indices):
                chosen = _take(contacts, indices)
                if objective == DesignObjective.K:  # readings only: each contact is the others' neighbour
                    sampled = calc_layout_readings(_layout(template, *params), chosen, num_rays, capacity)
                    return calc_neighbour_score(sampled.readings, jnp.asarray(targets)[indices], noise, balance), sampled
                information = calc_layout_information(_layout(template, *params), chosen, noise, num_rays, capacity)
                return calc_design_score(information.information, prior, objective), information

            @eqx.filter_jit
            def run(params, template, indices):
                (value, information), gradients = jax.value_and_grad(score, has_aux=True)(params, template, indices)
                return _Scored(value, gradients, jnp.any(information.did_overflow), jnp.max(information.needed, axis=0))

            cache[capacity] = run
        return cache[capacity](params, template, indices)

    return scorer


def _grown(compute, capacity):
    """run_growing with the capacity kept at powers of two (few compilations)."""
    result, fitted = run_growing(compute, capacity)
    return result, fitted.rounded_up()


def _score_layout(layout, contacts, targets, noise, prior, objective, num_rays, capacity, balance=1.0):
    """(score, each contact's Cramér–Rao bound (m), each contact's leave-one-out
    nearest-neighbour error (m), capacity): both error models, whatever the objective."""
    information, capacity = _grown(lambda c: _information_kernel(layout, contacts, noise, num_rays, c), capacity)
    return (*_score_information(information, targets, noise, prior, objective, balance), capacity)


def _score_information(information, targets, noise, prior, objective, balance=1.0):
    """(score, bounds, neighbour errors) of :func:`_score_layout` from a layout's
    LayoutInformation."""
    per_component = calc_neighbour_errors(information.readings, targets, noise, per_component=True)  # once: both the k score and the reported error
    if objective == DesignObjective.K:
        value = float(_balance_neighbour_errors(per_component, balance))
    else:
        value = float(calc_design_score(information.information, prior, objective))
    neighbour = np.sqrt(np.asarray(jnp.sum(per_component, axis=-1)))
    return value, np.asarray(calc_localisation_bounds(information.information, prior)), neighbour


@eqx.filter_jit
def _information_kernel(layout, contacts, noise, num_rays, capacity):
    return calc_layout_information(layout, contacts, noise, num_rays, capacity)


def _climb(region: FeasibleRegion, scorer, pool_score, template, positions, axes, sizes, config, capacity, rng, on_step):
    """Adam on the score from one feasible start (`config` a DesignConfig), each step's gradient over a fresh
    minibatch of the design's contacts, projecting after each step; every
    `eval_every` steps (and at the last) the whole pool is scored and the best layout
    so far kept. Returns (best positions, axes, sizes, the pool scores as (step,
    score) rows, capacity)."""
    import optax

    def adam(rate):
        return optax.adam(optax.cosine_decay_schedule(rate, max(config.steps, 1), alpha=0.1))

    optimiser = optax.multi_transform({"ports": adam(config.learning_rate), "angles": adam(config.axis_learning_rate)}, ("ports", "angles", "angles"))
    units = np.asarray(_size_units(template))
    params = (jnp.asarray(positions / POSITION_UNIT), jnp.asarray(axes), jnp.asarray(np.asarray(sizes) / units))
    state = optimiser.init(params)
    batch = min(config.batch, config.contacts)
    best, history, since = None, [], 0
    for step in range(config.steps + 1):
        indices = jnp.asarray(np.sort(rng.choice(config.contacts, size=batch, replace=False)))
        scored, capacity = _grown(lambda c, p=params, i=indices: scorer(c, template, p, i), capacity)
        last = step == config.steps
        if step % config.eval_every == 0 or last:
            value = float(scored.score) if batch == config.contacts else pool_score(params)
            history.append((step, value))
            if best is None or value > best[0] + 1e-9 * abs(best[0]):
                best, since = (value, *(np.asarray(p) for p in params)), 0
            else:
                since += config.eval_every
            on_step(value)
        else:
            on_step(None)
        if last or since >= config.patience:
            break
        gradients = scored.gradients if config.field_sizes else (scored.gradients[0], scored.gradients[1], jnp.zeros_like(params[2]))
        updates, state = optimiser.update(jax.tree_util.tree_map(lambda g: -g, gradients), state, params)
        moved = optax.apply_updates(params, updates)
        new_positions = region.project_positions(np.asarray(moved[0]) * POSITION_UNIT)
        new_axes = region.project_axes(np.asarray(moved[1]))
        new_sizes = np.clip(np.asarray(moved[2]) * units, MIN_FIELD_SIZE, np.where(np.asarray(template.is_cone), MAX_HALF_ANGLE, np.inf))
        params = (jnp.asarray(new_positions / POSITION_UNIT), jnp.asarray(new_axes), jnp.asarray(new_sizes / units))
    _, positions_mm, axes, sizes = best
    return positions_mm * POSITION_UNIT, axes / np.linalg.norm(axes, axis=1, keepdims=True), sizes * units, np.asarray(history), capacity
