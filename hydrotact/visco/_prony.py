"""Prony-series relaxation and the hereditary integral over a piecewise-linear input.

Linear viscoelasticity by the correspondence principle: the elastic response of the
sensor is linear in the modulus, so with the unit-modulus response u(t) (what a taxel
reads per pascal of E, or a force per pascal) the viscoelastic response is the
hereditary integral

    p(t) = ∫_{-∞}^{t} E(t − s) du(s)/ds ds,    E(t) = E∞ + Σᵢ Eᵢ exp(−t/τᵢ).

The input is at rest before the first sample: a non-zero u(t₀) is a step at t₀, so a
step input gives p(t) = E(t − t₀) u(t₀) exactly. Between samples u is linear, and each
term's internal state hᵢ obeys the exact update over a step Δ = tₙ₊₁ − tₙ with slope
r = (uₙ₊₁ − uₙ)/Δ:

    hᵢ(tₙ₊₁) = exp(−Δ/τᵢ) hᵢ(tₙ) + Eᵢ τᵢ r (1 − exp(−Δ/τᵢ)),

so p = E∞ u + Σᵢ hᵢ is exact for piecewise-linear u, at any (non-uniform) time steps.
The recursion is linear in h, which makes it an associative scan as well as a
sequential one: `method="scan"` runs it in a `lax.scan` (O(T · terms) work, T steps),
`method="associative"` in `lax.associative_scan` (the same work, O(log T) depth: the
faster one on a GPU and, vectorised, on a CPU).
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from .._errors import HydrotactError
from .._types import Array, Float


class Prony(eqx.Module):
    """A Prony relaxation modulus E(t) = E∞ + Σᵢ Eᵢ exp(−t/τᵢ) (a pytree).

    **Fields:** `long_term_modulus` E∞, Pa; `moduli` (num_terms,) Eᵢ, Pa; `taus`
    (num_terms,) τᵢ, s. E(0) = E∞ + Σ Eᵢ is the instantaneous modulus.
    """

    long_term_modulus: Float[Array, ""]
    moduli: Float[Array, " num_terms"]
    taus: Float[Array, " num_terms"]

    @property
    def num_terms(self) -> int:
        return self.moduli.shape[-1]

    @property
    def instantaneous_modulus(self):
        return self.long_term_modulus + jnp.sum(self.moduli, axis=-1)

    def calc_relaxation_modulus(self, times):
        """E(t) at `times` (any shape), Pa."""
        times = jnp.asarray(times)
        shape = (1,) * times.ndim + (-1,)
        decay = jnp.exp(-times[..., None] / self.taus.reshape(shape))
        return self.long_term_modulus + jnp.sum(self.moduli.reshape(shape) * decay, axis=-1)


def make_prony(long_term_modulus, moduli=(), taus=(), source: str | None = None) -> Prony:
    """A Prony series from numbers, checked on the host: E∞ > 0, Eᵢ ≥ 0, τᵢ > 0 and
    finite, as many τ as moduli. Terms are sorted by τ."""
    prefix = f"{source}: " if source else ""
    long_term = float(long_term_modulus)
    moduli = np.atleast_1d(np.asarray(moduli, dtype=np.float64))
    taus = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    if not np.isfinite(long_term) or long_term <= 0.0:
        raise HydrotactError(f"{prefix}long-term modulus must be a positive pressure in Pa, got {long_term:g}")
    if moduli.ndim != 1 or moduli.shape != taus.shape:
        raise HydrotactError(f"{prefix}{moduli.size} Prony moduli but {taus.size} relaxation times; give one tau per modulus")
    for k, (modulus, tau) in enumerate(zip(moduli, taus)):
        if not np.isfinite(modulus) or modulus < 0.0:
            raise HydrotactError(f"{prefix}Prony term {k + 1}: modulus must be a non-negative pressure in Pa, got {modulus:g}")
        if not np.isfinite(tau) or tau <= 0.0:
            raise HydrotactError(f"{prefix}Prony term {k + 1}: relaxation time must be positive, got {tau:g} s")
    order = np.argsort(taus, kind="stable")
    return Prony(jnp.asarray(long_term), jnp.asarray(moduli[order]), jnp.asarray(taus[order]))


def _linear_recurrence(decay, drive, start, method: str):
    """States hₙ of hₙ₊₁ = aₙ hₙ + bₙ from h₀ = `start`: decay, drive (T−1, K, C),
    start (K, C) -> (T, K, C)."""
    if decay.shape[0] == 0:  # one sample
        return start[None]
    if method == "scan":

        def step(state, inputs):
            a, b = inputs
            state = a * state + b
            return state, state

        _, states = jax.lax.scan(step, start, (decay, drive))
    elif method == "associative":

        def combine(earlier, later):
            a1, b1 = earlier
            a2, b2 = later
            return a1 * a2, a2 * b1 + b2

        # Fold the initial state into the first step so the scan starts from rest.
        drive = drive.at[0].add(decay[0] * start)
        _, states = jax.lax.associative_scan(combine, (decay, drive))
    else:
        raise ValueError(f"unknown method {method!r}; use 'associative' or 'scan'")
    return jnp.concatenate([start[None], states], axis=0)


def _kernel_terms(taus, times, values, restarts=None):
    """Per step and term: x = Δ/τ, the decay a = e^{−x} and the unit-modulus gain
    c = (1 − e^{−x})/x that multiplies the input increment (shapes (T−1, K, 1)).
    Where the next sample `restarts` (T,) the sequence, a = 0 (x and c are then
    those of a unit step, unused)."""
    steps = jnp.diff(times)
    if restarts is not None:
        steps = jnp.where(restarts[1:], 1.0, steps)  # a restart may step back in time
    ratio = (steps[:, None] / taus[None, :])[:, :, None]
    decay = jnp.exp(-ratio)
    if restarts is not None:
        decay = jnp.where(restarts[1:, None, None], 0.0, decay)
    return ratio, decay, -jnp.expm1(-ratio) / ratio


def _increments(values, restarts=None):
    """(T−1, 1, C) the input's increments; at a restart the new value itself (a step
    from rest)."""
    increments = jnp.diff(values, axis=0)
    if restarts is not None:
        increments = jnp.where(restarts[1:, None], values[1:], increments)
    return increments[:, None, :]


def _calc_kernel_responses(taus, times, values, method, restarts=None):
    """gₖ = (e^{−t/τₖ} ∗ u): the response of each unit-modulus term (T, K, C)."""
    _, decay, gain = _kernel_terms(taus, times, values, restarts)
    if restarts is not None:
        gain = jnp.where(restarts[1:, None, None], 1.0, gain)  # a step's response is its height
    drive = gain * _increments(values, restarts)
    start = jnp.broadcast_to(values[0], (taus.shape[0], values.shape[1]))  # the step at t0
    return _linear_recurrence(jnp.broadcast_to(decay, drive.shape), drive, start, method)


def calc_kernel_responses_and_derivatives(taus, times, values, method: str = "scan", restarts=None, with_derivatives: bool = True):
    """Each unit-modulus term's response gₖ = (e^{−t/τₖ} ∗ u) and its derivative
    ∂gₖ/∂τₖ, both (T, K, C) for values (T, C).

    Differentiating the update h' = a h + c Δu in τ, with x = Δ/τ:
    ∂h'/∂τ = a ∂h/∂τ + (x a / τ) h + ((1 − e^{−x})/x − e^{−x}) Δu / τ, from ∂h/∂τ = 0 at t₀.

    `restarts` (T,) bool, optional: the samples where the input starts again from
    rest (several sequences concatenated, each from its own t₀; the times may step
    back there). A restart's response is its value, whatever came before. Without
    `with_derivatives`, the derivatives are None.
    """
    ratio, decay, gain = _kernel_terms(taus, times, values, restarts)
    responses = _calc_kernel_responses(taus, times, values, method, restarts)
    if not with_derivatives:
        return responses, None
    increments = _increments(values, restarts)
    scale = taus[None, :, None]
    drive = (ratio * decay / scale) * responses[:-1] + ((gain - decay) / scale) * increments
    if restarts is not None:
        drive = jnp.where(restarts[1:, None, None], 0.0, drive)
    derivative = _linear_recurrence(jnp.broadcast_to(decay, drive.shape), drive, jnp.zeros_like(responses[0]), method)
    return responses, derivative


@functools.partial(jax.custom_jvp, nondiff_argnums=(3,))
def _kernel_responses(taus, times, values, method):
    return _calc_kernel_responses(taus, times, values, method)


@functools.partial(_kernel_responses.defjvp, symbolic_zeros=True)
def _kernel_responses_jvp(method, primals, tangents):
    """Forward mode with ∂g/∂τ computed once, not once per tangent direction: a fit's
    Jacobian pushes one tangent per parameter, and only the τ ones reach the kernel.

    ∂g/∂τ from :func:`calc_kernel_responses_and_derivatives`. The input enters
    linearly (g is linear in u); times are not differentiated.
    """
    taus, times, values = primals
    taus_dot, _, values_dot = tangents
    responses, derivative = calc_kernel_responses_and_derivatives(taus, times, values, method)
    tangent = jnp.zeros_like(responses)
    if not isinstance(taus_dot, SymbolicZero):
        tangent = tangent + derivative * taus_dot[None, :, None]
    if not isinstance(values_dot, SymbolicZero):
        tangent = tangent + _calc_kernel_responses(taus, times, values_dot, method)
    return responses, tangent


def calc_hereditary_integral(prony: Prony, times, unit_values, method: str = "scan"):
    """The viscoelastic response to a unit-modulus input sampled at `times` (pure).

    **Arguments:**

    - `prony`: the relaxation modulus.
    - `times`: (T,) strictly increasing sample times, s (steps may vary).
    - `unit_values`: (T, ...) the unit-modulus response u at those times (any trailing
      shape: taxels, force components); linear between samples, at rest before t₀.
    - `method`: "scan" (`lax.scan`) or "associative" (`lax.associative_scan`); the
      results agree to round-off.

    **Returns:** (T, ...) the response p(t), in the units of u times Pa.
    Differentiable in the Prony parameters and u (not in the times).
    """
    if method not in ("scan", "associative"):
        raise ValueError(f"unknown method {method!r}; use 'associative' or 'scan'")
    times = jnp.asarray(times)
    unit_values = jnp.asarray(unit_values)
    trailing = unit_values.shape[1:]
    values = unit_values.reshape(unit_values.shape[0], -1)  # (T, C)
    if prony.taus.shape[0] == 0 or values.shape[0] == 1:
        response = prony.instantaneous_modulus * values if values.shape[0] == 1 else prony.long_term_modulus * values
    else:
        responses = _kernel_responses(prony.taus, times, values, method)  # (T, K, C)
        response = prony.long_term_modulus * values + jnp.einsum("k,tkc->tc", prony.moduli, responses)
    return response.reshape((values.shape[0], *trailing))


def calc_contact_response(prony: Prony, times, unit_values, method: str = "scan"):
    """The viscoelastic response of a contact, which can push but never pull (pure).

    The hereditary integral (:func:`calc_hereditary_integral`) of a contact's elastic
    response turns negative after the probe lifts off: the relaxed skin "remembers"
    its load and, linearly superposed, would pull on the probe while it recovers. A
    contact cannot do that: a viscoelastic skin recovers more slowly than the probe
    leaves, so the contact is lost no later than in the elastic solution and its
    pressure stays ≥ 0. Hence, per component: the hereditary integral where it has
    the sign of the elastic response, 0 where the elastic response is 0 (no contact)
    or the signs differ. The memory (the terms' states) runs on regardless, so the
    next contact still starts from the residual stress of the earlier ones.

    **Arguments/Returns:** as :func:`calc_hereditary_integral`.
    """
    response = calc_hereditary_integral(prony, times, unit_values, method)
    return jnp.where(jnp.asarray(unit_values) * response > 0.0, response, 0.0)
