"""The fit's parameters and residuals (pure).

All parameters live in one flat vector x, positive ones as logarithms:

    log E∞
    log E₁ … log E_K, log τ₁ … log τ_K
    log gain  per free channel gain
    θ         per log and channel: offset = base + noise · θ

The residuals are (observed − model) / noise, stacked over logs, samples and columns.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..visco import Prony, calc_contact_response
from ._problem import FitProblem


class ParameterLayout(eqx.Module):
    """Where each parameter sits in x (static, hashable)."""

    num_terms: int = eqx.field(static=True)
    num_gains: int = eqx.field(static=True)
    channel_counts: tuple[int, ...] = eqx.field(static=True)

    @property
    def num_material(self) -> int:
        return 1 + 2 * self.num_terms

    @property
    def num_channels(self) -> int:
        return sum(self.channel_counts)

    @property
    def size(self) -> int:
        return self.num_material + self.num_gains + self.num_channels

    def names(self, problem: FitProblem) -> list[str]:
        """Parameter names, in x's order (as in the covariance matrix)."""
        names = ["log_long_term_modulus"]
        names += [f"log_modulus_{k + 1}" for k in range(self.num_terms)]
        names += [f"log_tau_{k + 1}" for k in range(self.num_terms)]
        names += [f"log_gain[{name}]" for name in problem.gain_names]
        labels = [f"{k + 1}/{channel}" for k, info in enumerate(problem.infos) for channel in info.channels]
        names += [f"offset[{label}]" for label in labels]
        return names

    def unpack(self, x):
        """x -> dict of named parameter arrays (natural scale where positive)."""
        at = 0

        def take(count):
            nonlocal at
            piece = x[at : at + count]
            at += count
            return piece

        long_term = jnp.exp(take(1)[0])
        moduli = jnp.exp(take(self.num_terms))
        taus = jnp.exp(take(self.num_terms))
        gains = jnp.exp(take(self.num_gains))
        offsets = take(self.num_channels)
        return {"prony": Prony(long_term, moduli, taus), "gains": gains, "offsets": offsets}


def make_layout(problem: FitProblem, num_terms: int) -> ParameterLayout:
    return ParameterLayout(num_terms=int(num_terms), num_gains=len(problem.gain_names), channel_counts=tuple(log.num_channels for log in problem.logs))


def calc_predictions(x, problem: FitProblem, layout: ParameterLayout, method: str = "scan"):
    """The model's channel readings (and forces) per log: a tuple of (T, C + F)."""
    parameters = layout.unpack(x)
    prony = parameters["prony"]
    gains_all = jnp.concatenate([parameters["gains"], jnp.ones((1,), x.dtype)])
    predictions = []
    first = 0
    for log, count in zip(problem.logs, layout.channel_counts):
        offsets = log.offset_base + log.offset_scale * parameters["offsets"][first : first + count]
        first += count
        response = calc_contact_response(prony, log.times, log.inputs, method=method)
        gains = gains_all[log.gain_index]  # index -1 picks the fixed 1
        channels = offsets[None, :] + gains[None, :] * response[:, :count]
        predictions.append(jnp.concatenate([channels, response[:, count:]], axis=1))
    return tuple(predictions)


def calc_residuals(x, problem: FitProblem, layout: ParameterLayout):
    """Weighted residuals (observed − model) / noise of all logs, one flat vector."""
    predictions = calc_predictions(x, problem, layout)
    return jnp.concatenate([((log.observed - prediction) * log.weights).reshape(-1) for log, prediction in zip(problem.logs, predictions)])


def pack(layout: ParameterLayout, *, long_term, moduli, taus, gains, offsets) -> np.ndarray:
    """The flat x from natural-scale numbers (host)."""
    pieces = [np.log([long_term])]
    pieces += [np.log(np.asarray(moduli, dtype=np.float64)), np.log(np.asarray(taus, dtype=np.float64))]
    pieces += [np.log(np.asarray(gains, dtype=np.float64)), np.asarray(offsets, dtype=np.float64)]
    x = np.concatenate([np.atleast_1d(piece) for piece in pieces])
    assert x.shape == (layout.size,)
    return x
