"""The fit's parameters and residuals (pure).

All parameters live in one flat vector x, positive ones as logarithms:

    log E∞
    log E₁ … log E_K, log τ₁ … log τ_K
    log gain  per free channel gain (relative gains: all but the reference's last,
              whose log is minus the reference's others' sum: the reference's
              geometric mean is 1; the outliers after it, free)
    θ         per log, channel and drift column: baseline = base + noise · (drift @ θ)
    u         per fitted rig parameter (stage logs): value = centre + half · tanh(u)

The residuals are (observed − model) / noise, stacked over logs, samples and columns.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..visco import Prony, calc_contact_response
from ._problem import FitProblem
from ._rig_problem import rig_log_inputs, rig_values


class ParameterLayout(eqx.Module):
    """Where each parameter sits in x (static, hashable)."""

    num_terms: int = eqx.field(static=True)
    num_gains: int = eqx.field(static=True)
    channel_counts: tuple[int, ...] = eqx.field(static=True)
    drift_sizes: tuple[int, ...] = eqx.field(static=True, default=())  # D per log (default 1)
    rig_free: tuple[int, ...] = eqx.field(static=True, default=())  # the fitted rig parameters (RigArrays.names' indices)
    relative_gains: bool = eqx.field(static=True, default=False)
    num_reference_gains: int = eqx.field(static=True, default=0)  # relative: the first gains, geometric mean 1

    @property
    def derived_gain(self) -> int | None:
        """The gain that x does not hold (relative gains: the reference's last), or None."""
        return self.num_reference_gains - 1 if self.relative_gains and self.num_reference_gains else None

    @property
    def num_gain_parameters(self) -> int:
        """The gains' entries in x: one fewer than the gains where they are relative."""
        return self.num_gains - (self.derived_gain is not None)

    @property
    def num_material(self) -> int:
        return 1 + 2 * self.num_terms

    @property
    def num_channels(self) -> int:
        return sum(self.channel_counts)

    @property
    def drifts(self) -> tuple[int, ...]:
        return self.drift_sizes or (1,) * len(self.channel_counts)

    @property
    def num_offsets(self) -> int:
        return sum(c * d for c, d in zip(self.channel_counts, self.drifts))

    @property
    def size(self) -> int:
        return self.num_material + self.num_gain_parameters + self.num_offsets + len(self.rig_free)

    def names(self, problem: FitProblem) -> list[str]:
        """Parameter names, in x's order (as in the covariance matrix)."""
        names = ["log_long_term_modulus"]
        names += [f"log_modulus_{k + 1}" for k in range(self.num_terms)]
        names += [f"log_tau_{k + 1}" for k in range(self.num_terms)]
        names += [f"log_gain[{name}]" for k, name in enumerate(problem.gain_names) if k != self.derived_gain]
        for k, (info, size) in enumerate(zip(problem.infos, self.drifts)):
            for channel in info.channels:
                names += [f"offset[{k + 1}/{channel}]"] if size == 1 else [f"drift[{k + 1}/{channel}/{j + 1}]" for j in range(size)]
        if self.rig_free:
            names += [f"rig[{problem.rig.names[k]}]" for k in self.rig_free]
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
        log_gains = take(self.num_gain_parameters)
        if self.derived_gain is not None:
            k = self.derived_gain
            log_gains = jnp.concatenate([log_gains[:k], -jnp.sum(log_gains[:k], keepdims=True), log_gains[k:]])
        gains = jnp.exp(log_gains)
        offsets = take(self.num_offsets)
        rig = take(len(self.rig_free))
        return {"prony": Prony(long_term, moduli, taus), "gains": gains, "offsets": offsets, "rig": rig}


def make_layout(problem: FitProblem, num_terms: int) -> ParameterLayout:
    return ParameterLayout(
        num_terms=int(num_terms), num_gains=len(problem.gain_names), channel_counts=tuple(log.num_channels for log in problem.logs),
        drift_sizes=tuple(int(log.drift.shape[1]) for log in problem.logs), rig_free=() if problem.rig is None else problem.rig.free,
        relative_gains=problem.relative_gains, num_reference_gains=problem.num_reference_gains,
    )


def calc_inputs(rig_u, problem: FitProblem, layout: ParameterLayout):
    """Each log's unit responses (T, C + F): the log's own, or, for stage logs, read
    off the rig's table at the fitted rig parameters' u (`layout.unpack(x)["rig"]`)."""
    if problem.rig is None:
        return tuple(log.inputs for log in problem.logs)
    values = rig_values(problem.rig, layout.rig_free, rig_u)
    return tuple(rig_log_inputs(problem.rig, values, k, log.times) for k, log in enumerate(problem.logs))


def calc_predictions(x, problem: FitProblem, layout: ParameterLayout, method: str = "scan"):
    """The model's channel readings (and forces) per log: a tuple of (T, C + F)."""
    parameters = layout.unpack(x)
    prony = parameters["prony"]
    gains_all = jnp.concatenate([parameters["gains"], jnp.ones((1,), x.dtype)])
    predictions = []
    first = 0
    for log, inputs, count, size in zip(problem.logs, calc_inputs(parameters["rig"], problem, layout), layout.channel_counts, layout.drifts):
        theta = parameters["offsets"][first : first + count * size].reshape(count, size)
        first += count * size
        baselines = log.offset_base[None, :] + log.offset_scale[None, :] * (log.drift @ theta.T)  # (T, C)
        response = calc_contact_response(prony, log.times, inputs, method=method)
        gains = gains_all[log.gain_index]  # index -1 picks the fixed 1
        channels = baselines + gains[None, :] * response[:, :count]
        predictions.append(jnp.concatenate([channels, response[:, count:]], axis=1))
    return tuple(predictions)


def calc_residuals(x, problem: FitProblem, layout: ParameterLayout):
    """Weighted residuals (observed − model) / noise of all logs, one flat vector."""
    predictions = calc_predictions(x, problem, layout)
    return jnp.concatenate([((log.observed - prediction) * log.weights).reshape(-1) for log, prediction in zip(problem.logs, predictions)])


def pack(layout: ParameterLayout, *, long_term, moduli, taus, gains, offsets, rig=()) -> np.ndarray:
    """The flat x from natural-scale numbers (host; `rig` the fitted rig parameters'
    u, :func:`rig_start`)."""
    pieces = [np.log([long_term])]
    pieces += [np.log(np.asarray(moduli, dtype=np.float64)), np.log(np.asarray(taus, dtype=np.float64))]
    log_gains = np.log(np.asarray(gains, dtype=np.float64))
    if layout.derived_gain is not None:  # relative: the reference's last follows from the others
        log_gains = np.delete(log_gains, layout.derived_gain)
    pieces += [log_gains, np.asarray(offsets, dtype=np.float64), np.asarray(rig, dtype=np.float64)]
    x = np.concatenate([np.atleast_1d(piece) for piece in pieces])
    assert x.shape == (layout.size,)
    return x
