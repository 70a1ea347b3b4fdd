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
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._choices import Choice
from .._types import Array, Bool, Float, Int
from ..taxel import TaxelCapacity, TaxelLayout, calc_taxel_pressures
from ._contacts import DesignContacts


class DesignObjective(Choice):
    """`d`: maximise the mean log-determinant of the information (D-optimal);
    `a`: minimise the mean Cramér–Rao bound on the localisation error (A-optimal)."""

    D = "d"
    A = "a"


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
        # A = dθ/dq: u and v pass, F(q); J_θ = J_q A⁻¹ with A⁻¹ = [[1, 0, 0], [0, 1, 0], -F_q[:2]/F_d, 1/F_d].
        f_u, f_v, f_d = force_jacobian
        inverse = jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-f_u / f_d, -f_v / f_d, 1.0 / f_d]])
        readings = contacts.modulus * tau
        jacobian = contacts.modulus * d_tau @ inverse
        heard = (readings < noise.limit)[:, None]
        weighted = jnp.where(heard, jacobian, 0.0) / jnp.sqrt(noise.variances(readings))[:, None]
        return weighted.T @ weighted, readings, sampled.did_overflow, sampled.needed

    information, readings, overflow, needed = jax.vmap(one)(contacts.surfaces, contacts.tangents, contacts.force_jacobians)
    return LayoutInformation(information, readings, overflow, needed)


def calc_prior_precision(skin_area: float, forces) -> jnp.ndarray:
    """I₀ (3, 3): contacts spread uniformly over a square the skin's area (variance
    area/12 along each of u and v) and forces with the spread of the drawn ones."""
    return jnp.diag(jnp.array([12.0 / skin_area, 12.0 / skin_area, 1.0 / jnp.maximum(jnp.var(forces), 1e-12)]))


def calc_localisation_bounds(information, prior) -> jnp.ndarray:
    """The Cramér–Rao bound on each contact's RMS localisation error, m: the root of the
    trace of the (u, v) block of (I + I₀)⁻¹."""
    covariance = jnp.linalg.inv(information + jnp.broadcast_to(prior, information.shape))
    return jnp.sqrt(covariance[..., 0, 0] + covariance[..., 1, 1])


def calc_design_score(information, prior, objective: DesignObjective) -> jnp.ndarray:
    """The score a design maximises: the mean log det(I + I₀) (`d`), or minus the mean
    squared localisation bound in mm² (`a`)."""
    if objective == DesignObjective.D:
        return jnp.mean(jnp.linalg.slogdet(information + jnp.broadcast_to(prior, information.shape))[1])
    return -jnp.mean(calc_localisation_bounds(information, prior) ** 2) * 1e6
