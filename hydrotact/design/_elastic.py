"""Designing a layout of elastic barometers: their readings linearised in the ports,
moved within a trust region (host driver with pure kernels).

An elastic barometer's reading of a contact is the contact's tractions integrated
against its receptive field w(x_b, a_b) (:mod:`hydrotact.elastic`), and the field is
the solution of one elastic solve for the port's functional: moving a port changes
it. A layout design takes hundreds of steps, and a solve per barometer per step is
what a design cannot afford, so the readings are linearised around an expansion
layout, exactly: with the fields' derivatives along each port's position and axis
(one solve per direction, :func:`hydrotact.elastic.calc_field_derivatives`),

    y_b(c; x, a) ~ y_b(c; x0, a0) + dy_b/dx (x - x0) + dy_b/da (a - a0),

each term a contact's tractions integrated against a field, and likewise their
derivatives along the contact's parameters (for the information objectives). Every
term is computed once per expansion; a step of the optimiser is then as cheap as for
ray-cast taxels, and its gradient is the exact gradient of the readings at the
expansion. The optimiser moves each port no further than `trust_radius` from its
expansion; after a round of steps the layout it reached is solved exactly (new
fields, the exact score) and becomes the next expansion when it scores better, while
a round that scored worse is undone and the radius halved (a trust region: the
linearisation is only believed near where it was made).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Float
from ._objective import LayoutInformation, calc_contact_information

TRUST_RADIUS = 1.0e-3
"""How far (m) a round may move a port from its expansion before the fields are solved
again (the fields vary over the rubber's depth, millimetres: within a millimetre the
linearised readings of sphere8 stay within a few per cent)."""
TRUST_AXIS = 0.15
"""How far (in the unit axis vector's components) a round may turn a normal-stress
port's axis."""


class ElasticReadout(eqx.Module):
    """Elastic barometers' unit readings of a set of contacts (per pascal of E),
    linearised around the expansion ports (a pytree; C contacts, B barometers).

    **Fields:** `positions`, `axes` (B, 3): the expansion; `tau` (C, B) the readings
    there and `tau_q` (C, B, 3) along each contact's q = (u, v, d); `d_positions`
    (C, B, 3) and `d_axes` (C, B, 3) their derivatives along each port's position
    (per m) and axis, and `d_positions_q`, `d_axes_q` (C, B, 3, 3) those along q (the
    last axis)."""

    positions: Float[Array, "num_barometers 3"]
    axes: Float[Array, "num_barometers 3"]
    tau: Float[Array, "num_contacts num_barometers"]
    tau_q: Float[Array, "num_contacts num_barometers 3"]
    d_positions: Float[Array, "num_contacts num_barometers 3"]
    d_axes: Float[Array, "num_contacts num_barometers 3"]
    d_positions_q: Float[Array, "num_contacts num_barometers 3 3"]
    d_axes_q: Float[Array, "num_contacts num_barometers 3 3"]

    def at(self, positions, axes):
        """(tau (C, B), tau_q (C, B, 3)) at the layout (positions (B, 3) m, unit axes)."""
        dx, da = positions - self.positions, axes - self.axes
        tau = self.tau + jnp.einsum("cbk,bk->cb", self.d_positions, dx) + jnp.einsum("cbk,bk->cb", self.d_axes, da)
        tau_q = self.tau_q + jnp.einsum("cbkj,bk->cbj", self.d_positions_q, dx) + jnp.einsum("cbkj,bk->cbj", self.d_axes_q, da)
        return tau, tau_q

    def take(self, indices):
        """The readout of the contacts `indices`."""
        return eqx.tree_at(
            lambda r: (r.tau, r.tau_q, r.d_positions, r.d_axes, r.d_positions_q, r.d_axes_q),
            self,
            tuple(jnp.asarray(a)[indices] for a in (self.tau, self.tau_q, self.d_positions, self.d_axes, self.d_positions_q, self.d_axes_q)),
        )


def calc_readout_information(readout: ElasticReadout, positions, axes, contacts, noise) -> LayoutInformation:
    """The layout's information and readings for each contact (pure; differentiable in
    the positions and axes), as :func:`calc_layout_information` for ray-cast taxels."""
    tau, tau_q = readout.at(positions, axes)
    information, readings = jax.vmap(lambda t, tq, f: calc_contact_information(t, tq, f, contacts.modulus, noise))(tau, tau_q, contacts.force_jacobians)
    count = tau.shape[0]
    return LayoutInformation(information, readings, jnp.zeros(count, dtype=bool), jnp.zeros((count, 2), dtype=jnp.int32))


@eqx.filter_jit
def _contact_terms(fields, stack, surfaces, tangents):
    """Per contact, the readings of `stack` (M, num_nodes, B, 3) fields and their
    derivatives along the contact's three tangents: (C, M, B), (C, M, B, 3)."""
    from ..elastic import calc_elastic_readings

    def read(surface):
        return jax.vmap(lambda responses: calc_elastic_readings(eqx.tree_at(lambda f: f.responses, fields, responses), surface))(stack)

    def one(args):
        surface, tangent = args
        value = read(surface)
        along = jax.vmap(lambda t: jax.jvp(read, (surface,), (t,))[1])(tangent)  # (3, M, B)
        return value, jnp.moveaxis(along, 0, -1)

    return jax.lax.map(one, (surfaces, tangents), batch_size=8)


class ElasticDesigner:
    """The elastic barometers of a design (host): their ports' radii and readings, the
    mesh and nu, and the readouts of contact sets at any layout (fields and their
    derivatives solved, and cached by content, per barometer as needed)."""

    def __init__(self, mesh, poisson_ratio: float, port_radii, readings, source: str | None = None, progress: bool = False):
        self.mesh, self.poisson_ratio, self.source, self.progress = mesh, float(poisson_ratio), source, progress
        self.port_radii = np.asarray(port_radii, dtype=np.float64)
        self.readings = list(readings)

    def readout(self, positions, axes, contacts, derivatives: bool = True) -> ElasticReadout:
        """The readout of `contacts` (DesignContacts) at the layout (positions (B, 3) m,
        axes (B, 3)): linearised there (`derivatives`), or the readings alone (exact at
        this layout, zero derivatives)."""
        from ..elastic import make_field_derivatives, make_receptive_fields

        positions, axes = np.asarray(positions, dtype=np.float64), np.asarray(axes, dtype=np.float64)
        axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        args = (self.mesh, positions, axes, self.port_radii, self.readings, self.poisson_ratio)
        fields = make_receptive_fields(*args, progress=self.progress, source=self.source)
        stack = [fields.responses]
        if derivatives:
            found = make_field_derivatives(*args, progress=self.progress, source=self.source)
            stack += [found.positions[..., k] for k in range(3)] + [found.axes[..., k] for k in range(3)]
        value, along = _contact_terms(fields, jnp.stack(stack), contacts.surfaces, contacts.tangents)
        count, num_barometers = value.shape[0], value.shape[2]
        zeros = jnp.zeros((count, num_barometers, 3), value.dtype)
        zeros_q = jnp.zeros((count, num_barometers, 3, 3), value.dtype)
        return ElasticReadout(
            positions=jnp.asarray(positions),
            axes=jnp.asarray(axes),
            tau=value[:, 0],
            tau_q=along[:, 0],
            d_positions=jnp.moveaxis(value[:, 1:4], 1, -1) if derivatives else zeros,
            d_axes=jnp.moveaxis(value[:, 4:7], 1, -1) if derivatives else zeros,
            d_positions_q=jnp.moveaxis(along[:, 1:4], 1, 2) if derivatives else zeros_q,
            d_axes_q=jnp.moveaxis(along[:, 4:7], 1, 2) if derivatives else zeros_q,
        )


def _clip_to_balls(points, centres, radius: float):
    """Each point (n, 3) moved onto the ball of `radius` about its centre where it lies
    outside it."""
    offsets = np.asarray(points) - centres
    lengths = np.linalg.norm(offsets, axis=1, keepdims=True)
    return centres + offsets * np.minimum(1.0, radius / np.maximum(lengths, 1e-300))


class TrustRegion:
    """A feasible region whose position projection also keeps each port within
    `radius` of its expansion (and each axis within `axis_radius`), the round's trust
    region; :meth:`violations` are the feasible region's."""

    def __init__(self, region, centres, axes, radius: float, axis_radius: float = TRUST_AXIS):
        self.region, self.centres, self.centre_axes = region, np.asarray(centres), np.asarray(axes)
        self.radius, self.axis_radius = float(radius), float(axis_radius)

    def project_positions(self, positions):
        return self.region.project_positions(_clip_to_balls(positions, self.centres, self.radius))

    def project_axes(self, axes):
        return self.region.project_axes(_clip_to_balls(axes, self.centre_axes, self.axis_radius))

    def violations(self, positions, axes):
        return self.region.violations(positions, axes)


def _make_elastic_scorer(readout: ElasticReadout, contacts, targets, noise, prior, objective, balance=1.0):
    """The scorer of :func:`hydrotact.design._search._make_scorer` over a readout
    (capacity is not used: elastic readings have no buffers)."""
    from ._objective import DesignObjective, calc_design_score, calc_neighbour_score
    from ._search import POSITION_UNIT, _Scored, _take

    def score(params, indices):
        positions, axes = params[0] * POSITION_UNIT, params[1] / jnp.linalg.norm(params[1], axis=1, keepdims=True)
        chosen = readout.take(indices)
        if objective == DesignObjective.K:
            tau, _ = chosen.at(positions, axes)
            return calc_neighbour_score(contacts.modulus * tau, jnp.asarray(targets)[indices], noise, balance)
        information = calc_readout_information(chosen, positions, axes, _take(contacts, indices), noise)
        return calc_design_score(information.information, prior, objective)

    @eqx.filter_jit
    def run(params, indices):
        value, gradients = jax.value_and_grad(score)(params, indices)
        return _Scored(value, gradients, jnp.asarray(False), jnp.zeros(2, dtype=jnp.int32))

    return lambda capacity, template, params, indices: run(params, indices)


def climb_elastic(designer: ElasticDesigner, region, contacts, targets, noise, prior, objective, template, positions, axes, sizes, config, capacity, rng, on_step, exact_score):
    """One start of an elastic design (see the module): `config.expansions` rounds of
    :func:`hydrotact.design._search._climb` on the readings linearised at the round's
    expansion, each kept within its trust region; `exact_score(readout, positions,
    axes)` scores a layout from its exact readout. Returns what `_climb` does, the
    history the exact scores after each round (step, score)."""
    import dataclasses

    from ._search import _climb

    rounds = max(1, int(config.expansions))
    per_round = -(-config.steps // rounds)
    radius = float(config.trust_radius)
    centre = (np.asarray(positions), np.asarray(axes) / np.linalg.norm(axes, axis=1, keepdims=True))
    readout = designer.readout(*centre, contacts)
    best = exact_score(readout, *centre)
    history = [(0, best)]
    sub = dataclasses.replace(config, steps=per_round)
    everything = jnp.arange(config.contacts)
    shown = [0]

    def on_round_step(value):  # the rounds' steps, counted against the start's (one more each)
        if shown[0] < config.steps:
            shown[0] += 1
            on_step(value)
    for round_ in range(rounds):
        scorer = _make_elastic_scorer(readout, contacts, targets, noise, prior, objective, config.balance)

        def pool_score(params, scorer=scorer):
            return float(scorer(None, None, params, everything).score)

        moved_positions, moved_axes, _, _, capacity = _climb(
            TrustRegion(region, centre[0], centre[1], radius), scorer, pool_score, template, *centre, sizes, sub, capacity, rng, on_round_step
        )
        exact = designer.readout(moved_positions, moved_axes, contacts, derivatives=False)
        value = exact_score(exact, moved_positions, moved_axes)
        history.append(((round_ + 1) * per_round, value))
        if value > best:
            best, centre = value, (moved_positions, moved_axes)
            if round_ + 1 < rounds:
                readout = designer.readout(*centre, contacts)
        else:
            radius /= 2.0  # the linearisation was not to be believed that far
    return centre[0], centre[1], np.asarray(sizes), np.asarray(history), capacity
