"""What a layout's readings say about a contact: the Fisher information of (where on the
skin, how hard) under the barometers' noise, and the design objectives built on it.

For a contact with parameters θ = (u, v, F) (u, v the displacement along the skin, m;
F the force along the approach, N) the readings are y = E τ(θ) (Pa; τ the taxels' unit
pressures, E the material's E(0)), each with independent Gaussian noise of variance

    σᵢ² = noise_rms² + LSB²/12 + floor² + (relative_noise · yᵢ)²

(the part's white noise, its quantisation, a floor for what a cast barometer does
besides (slow drift with temperature, the silicone's creep and hysteresis: a contact
reading less than this says little), and a part proportional to the reading: a cast
barometer's gain, which an estimator knows only to within a few per cent). The floor
also keeps the score smooth: with the part's 0.03 Pa alone a barely seen contact (a
few pascals at a receptive field's rim) carries as much information as a well seen
one, and the score jumps as field rims sweep over contacts (measured on sphere8, 32
contacts: steps of 0.1 mm and 0.01 rad along the gradient's signs lost 0.48 of the
score; with a 20 Pa floor they gained 0.27, and 0.3 mm gained 0.92). A
channel at the top of its range reads its limit and says nothing. The information is
I(θ) = Jᵀ Σ⁻¹ J with J = ∂y/∂θ, from the linearised contact: J = E ∂τ/∂q A⁻¹ with
q = (u, v, d) and A = ∂θ/∂q (u and v pass through; F(q) from the contact's force).

A layout is scored by the Bayesian design criteria of that information plus a prior
precision I₀ (the spread of contacts over the skin and of forces over their range,
which keeps contacts no barometer sees finite instead of -inf):

- **D-optimal** (`d`, the default): the mean over contacts of log det(I + I₀),
  maximised (the volume of the posterior's confidence ellipsoid, shrunk).
- **A-optimal** (`a`): the mean over contacts of the Cramér–Rao bound on the squared
  localisation error, trace of the (u, v) block of (I + I₀)⁻¹, minimised; reported as
  its root, the RMS localisation error an unbiased estimator could at best reach (m).

The bound is local: it says how well a contact could be told from its close
neighbours by an estimator that knew the readings' map exactly. A learned estimator
knows the map only at its training contacts, and between them it interpolates. On
sphere8's layouts the bound did not rank the trained binned GRU's localisation errors
(the layout with the lowest bound, 3.4 mm, trained to 4.5 mm, behind the built-in's
4.3 mm at a bound of 5.0 mm), while the leave-one-out error of a five-nearest-neighbour
estimator on 384 static presses ranked the five layouts' trained arc lengths in order,
and the same estimator run on each layout's dataset ranked their trained θ RMSE in
order (experiments/layout_design.py; benchmarks/RESULTS.md): the trained estimator
sits on what its training presses let any learner reach. Hence

- **learned** (`k`): the mean over contacts of the squared error (mm²) of a soft
  five-nearest-neighbour estimate of where the contact is, learned from the other
  contacts' readings (leave one out), minimised; reported as its root (m). Where is
  what a trained estimator is scored on (:func:`calc_neighbour_targets`): on a sensor
  with contact angles, the angles (θ, φ) times the skin's mean radius about the
  contact centre (so an error is an arc, in m, weighing θ and φ as their RMSEs do);
  otherwise the contact point. (Scored on the contact point, a design on sphere8 cut
  the trained θ RMSE by a quarter and the arc length by a tenth, and lost φ: it traded
  the long φ direction of the skin, 180 deg against θ's 90, for θ.) The readings are compared as asinh(y / s) (s the noise at zero
  reading: linear within the noise, logarithmic, i.e. relative, above it), clipped at
  the channel's limit; the weights are a softmax of minus the squared feature distance
  over the query's squared distance to its fifth neighbour (an order statistic:
  continuous, differentiable but where two neighbours swap), so the estimate is
  continuous in the layout and its gradient exact almost everywhere.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._choices import Choice
from .._linalg import inv, slogdet
from .._types import Array, Bool, Float, Int
from ..taxel import TaxelCapacity, TaxelLayout, calc_taxel_pressures
from ._contacts import DesignContacts


class DesignObjective(Choice):
    """`d`: maximise the mean log-determinant of the information (D-optimal);
    `a`: minimise the mean Cramér–Rao bound on the localisation error (A-optimal);
    `k`: minimise the leave-one-out localisation error of a nearest-neighbour
    estimator learned from the contacts' readings (see the module)."""

    D = "d"
    A = "a"
    K = "k"


NEIGHBOURS = 5
"""The nearest-neighbour estimator's k for the `k` objective."""


class NoiseModel(eqx.Module):
    """The barometers' noise (Pa) and range for the information (see the module).

    **Fields:** `noise_rms` (Pa), `lsb` (Pa), `floor` (Pa), `relative_noise`
    (fraction of the reading), `limit` the largest pressure a channel reads above
    ambient before it clips (Pa)."""

    noise_rms: Float[Array, ""]
    lsb: Float[Array, ""]
    floor: Float[Array, ""]
    relative_noise: Float[Array, ""]
    limit: Float[Array, ""]

    def variances(self, readings):
        return self.noise_rms**2 + self.lsb**2 / 12.0 + self.floor**2 + (self.relative_noise * readings) ** 2


class LayoutInformation(eqx.Module):
    """The information a layout's readings carry about each contact.

    **Fields:** `information` (N, 3, 3) Fisher information of (u, v, F) in m⁻² and N⁻²
    (the prior not included); `readings` (N, num_taxels) Pa above ambient;
    `did_overflow` and `needed` (N, 2) of the taxel sampler's buffers."""

    information: Float[Array, "num_contacts 3 3"]
    readings: Float[Array, "num_contacts num_taxels"]
    did_overflow: Bool[Array, " num_contacts"]
    needed: Int[Array, "num_contacts 2"]


def calc_layout_information(
    layout: TaxelLayout, contacts: DesignContacts, noise: NoiseModel, num_rays: int, capacity: TaxelCapacity = TaxelCapacity()
) -> LayoutInformation:
    """The Fisher information of each contact's (u, v, F) in the layout's readings
    (pure; jittable and differentiable in the layout's positions, axes and field sizes)."""

    def one(surface, tangents, force_jacobian):
        def pressures(s):
            readings = calc_taxel_pressures(layout, s, num_rays, capacity)
            return readings.pressures, readings

        tau, sampled = pressures(surface)
        d_tau = jax.vmap(lambda t: jax.jvp(lambda s: pressures(s)[0], (surface,), (t,))[1])(tangents).T  # (T, 3) per unit q
        information, readings = calc_contact_information(tau, d_tau, force_jacobian, contacts.modulus, noise)
        return information, readings, sampled.did_overflow, sampled.needed

    information, readings, overflow, needed = jax.vmap(one)(contacts.surfaces, contacts.tangents, contacts.force_jacobians)
    return LayoutInformation(information, readings, overflow, needed)


def calc_contact_information(tau, d_tau, force_jacobian, modulus, noise: NoiseModel):
    """One contact's Fisher information of (u, v, F) (3, 3) and readings (T,) Pa from
    its unit readings `tau` (T,) (per pascal of E) and their derivatives `d_tau`
    (T, 3) along q = (u, v, d), its force's `force_jacobian` dF/dq (3,) (pure)."""
    # A = dθ/dq: u and v pass, F(q); J_θ = J_q A⁻¹ with A⁻¹ = [[1, 0, 0], [0, 1, 0], -F_q[:2]/F_d, 1/F_d].
    # A press that does not touch (a drawn depth where the skin gives no force) has no
    # F to learn: it carries no information (the prior keeps it finite).
    f_u, f_v, f_d = force_jacobian
    touching = f_d > 0.0
    f_d = jnp.where(touching, f_d, 1.0)
    inverse = jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-f_u / f_d, -f_v / f_d, 1.0 / f_d]])
    readings = modulus * tau
    jacobian = modulus * d_tau @ inverse
    heard = (readings < noise.limit)[:, None] & touching
    weighted = jnp.where(heard, jacobian, 0.0) / jnp.sqrt(noise.variances(readings))[:, None]
    return weighted.T @ weighted, readings


def calc_prior_precision(skin_area: float, forces) -> jnp.ndarray:
    """I₀ (3, 3): contacts spread uniformly over a square the skin's area (variance
    area/12 along each of u and v) and forces with the spread of the drawn ones."""
    return jnp.diag(jnp.array([12.0 / skin_area, 12.0 / skin_area, 1.0 / jnp.maximum(jnp.var(forces), 1e-12)]))


def calc_localisation_bounds(information, prior) -> jnp.ndarray:
    """The Cramér–Rao bound on each contact's RMS localisation error, m: the root of the
    trace of the (u, v) block of (I + I₀)⁻¹."""
    covariance = inv(information + jnp.broadcast_to(prior, information.shape))
    return jnp.sqrt(covariance[..., 0, 0] + covariance[..., 1, 1])


def calc_design_score(information, prior, objective: DesignObjective) -> jnp.ndarray:
    """The score a design maximises: the mean log det(I + I₀) (`d`), or minus the mean
    squared localisation bound in mm² (`a`)."""
    if objective == DesignObjective.D:
        return jnp.mean(slogdet(information + jnp.broadcast_to(prior, information.shape))[1])
    return -jnp.mean(calc_localisation_bounds(information, prior) ** 2) * 1e6


class LayoutReadings(eqx.Module):
    """A layout's readings of each contact, without their derivatives.

    **Fields:** `readings` (N, num_taxels) Pa above ambient; `did_overflow` and
    `needed` (N, 2) of the taxel sampler's buffers."""

    readings: Float[Array, "num_contacts num_taxels"]
    did_overflow: Bool[Array, " num_contacts"]
    needed: Int[Array, "num_contacts 2"]


def calc_layout_readings(layout: TaxelLayout, contacts: DesignContacts, num_rays: int, capacity: TaxelCapacity = TaxelCapacity()) -> LayoutReadings:
    """Each contact's readings in the layout, Pa above ambient (pure; jittable and
    differentiable in the layout)."""
    sampled = jax.vmap(lambda surface: calc_taxel_pressures(layout, surface, num_rays, capacity))(contacts.surfaces)
    return LayoutReadings(contacts.modulus * sampled.pressures, sampled.did_overflow, sampled.needed)


def calc_neighbour_targets(points_S, contact_center_S=None) -> jnp.ndarray:
    """What the learned objective estimates of each contact (N, D), m: with a contact
    centre, the contact angles (θ, φ) of :func:`hydrotact.sim.calc_contact_angles`
    times the points' mean distance from it; without, the points (N, 3)."""
    if contact_center_S is None:
        return jnp.asarray(points_S)
    from ..sim import calc_contact_angles

    points = jnp.asarray(points_S)
    centre = jnp.asarray(contact_center_S)[None, :]
    radius = jnp.mean(jnp.linalg.norm(points - centre, axis=-1))
    return radius * jnp.stack(calc_contact_angles(points, centre), axis=-1)


def calc_neighbour_features(readings, noise: NoiseModel) -> jnp.ndarray:
    """What the learned objective's estimator compares: asinh(y / s) of the readings
    `y` (..., T) Pa above ambient, clipped at the channel's limit, s the noise at zero
    reading (linear within the noise, logarithmic above it)."""
    return jnp.arcsinh(jnp.minimum(readings, noise.limit) / jnp.sqrt(noise.variances(0.0)))


def calc_neighbour_errors(readings, points, noise: NoiseModel, reference_readings=None, reference_points=None, per_component: bool = False) -> jnp.ndarray:
    """Each contact's squared localisation error under a soft
    :data:`NEIGHBOURS`-nearest-neighbour estimator of its target from the readings
    (see the module): learned from `reference_readings` (M, T) and `reference_points`
    (M, D), or, when they are None, from the other contacts (leave one out).
    `readings` (N, T) Pa above ambient; `points` (N, D) the targets (the contact
    points, or :func:`calc_neighbour_targets`), m, and the error in m² (N,), or with
    `per_component` each component's (N, D)."""
    leave_one_out = reference_readings is None
    reference_readings = readings if leave_one_out else reference_readings
    reference_points = points if leave_one_out else reference_points
    query, reference = calc_neighbour_features(readings, noise), calc_neighbour_features(reference_readings, noise)
    distances = jnp.sum((query[:, None, :] - reference[None, :, :]) ** 2, axis=-1)
    excluded = jnp.eye(distances.shape[0], distances.shape[1], dtype=bool) if leave_one_out else jnp.zeros(distances.shape, dtype=bool)
    k = min(NEIGHBOURS, reference.shape[0] - leave_one_out)
    width = jnp.sort(jnp.where(excluded, jnp.inf, distances), axis=1)[:, k - 1] + 1e-9  # identical readings: no 0/0
    weights = jax.nn.softmax(jnp.where(excluded, -jnp.inf, -distances / width[:, None]), axis=1)
    squared = (weights @ reference_points - points) ** 2
    return squared if per_component else jnp.sum(squared, axis=-1)


def calc_neighbour_score(readings, points, noise: NoiseModel, balance: float = 1.0) -> jnp.ndarray:
    """The `k` objective's score (higher is better), mm²: minus the `balance`-norm of
    the per-component mean leave-one-out squared errors of
    :func:`calc_neighbour_errors` (the targets' components: θ and φ as arcs, or x, y,
    z). `balance` 1 sums them (the mean squared error of the whole target); a larger
    one leans on the worst component, towards their maximum (see :class:`DesignConfig`)."""
    return _balance_neighbour_errors(calc_neighbour_errors(readings, points, noise, per_component=True), balance)


def _balance_neighbour_errors(per_component, balance: float = 1.0) -> jnp.ndarray:
    """:func:`calc_neighbour_score` from the per-component squared errors (N, D) m²
    of :func:`calc_neighbour_errors` (`per_component=True`), mm²."""
    return -jnp.sum(jnp.mean(per_component, axis=0) ** balance) ** (1.0 / balance) * 1e6
