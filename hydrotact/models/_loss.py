"""The training loss of an estimator and the paper's Table I metrics (pure JAX).

Targets per sample (a dict of arrays with a leading time/batch shape): `values` (...,
K) the spec's regression targets in order (N, m; NaN where unlabelled); `theta`, `phi`
(rad; NaN where there is no contact); `contact` (0 or 1, |F| > 0.1 N); and `mask` (1
where the sample counts: after a sequence's burn-in, inside the data).

Loss = w_force · MSE(forces, N²) + w_position · MSE(positions and depth as z-scores, on
contact samples) + w_angle · (cross-entropy over the bins, or the MSE of the angles, on
contact samples) + w_contact · BCE(contact logit). The paper weighs the contact BCE by
10; the others by 1 (:data:`DEFAULT_WEIGHTS`).
"""

import jax
import jax.numpy as jnp

from ._bins import calc_bin_index
from ._estimator import FORCES, EstimatorSpec, decode_estimator_outputs

DEFAULT_WEIGHTS = {"force": 1.0, "angle": 1.0, "contact": 10.0, "position": 1.0}


def _masked_mean(values, mask):
    return jnp.sum(values * mask) / jnp.maximum(jnp.sum(mask), 1.0)


def _masked_rms(values, mask):
    """The RMS over the samples `mask` counts; NaN where it counts none (a metric of
    nothing is not 0)."""
    count = jnp.sum(mask)
    return jnp.where(count > 0, jnp.sqrt(jnp.sum(values**2 * mask) / jnp.maximum(count, 1.0)), jnp.nan)


def calc_loss_terms(spec: EstimatorSpec, raw, targets: dict) -> dict:
    """Each loss term, averaged over the samples that count: `force` (N², mean over the
    force targets; 0 without any), `position` (the mean squared z-score of the position
    and depth targets, each over its labelled contact samples; 0 without any), `angle`
    (bin cross-entropy, or rad² unbinned; contact samples only; 0 on a sensor without
    angles), `contact` (BCE)."""
    mask = targets["mask"].astype(raw.dtype)
    layout = spec.outputs
    label = targets["contact"].astype(raw.dtype)
    forces = [k for k, name in enumerate(spec.targets) if name in FORCES]
    zero = jnp.zeros((), raw.dtype)
    if forces == list(range(len(forces))) and forces:  # they lead the outputs (the default: the four, in order)
        force = _masked_mean(jnp.mean((raw[..., : len(forces)] - targets["values"][..., : len(forces)]) ** 2, axis=-1), mask)
    elif forces:
        columns = jnp.asarray([layout[spec.targets[k]].start for k in forces])
        force = _masked_mean(jnp.mean((raw[..., columns] - targets["values"][..., jnp.asarray(forces)]) ** 2, axis=-1), mask)
    else:
        force = zero
    position = zero
    others = [k for k, name in enumerate(spec.targets) if name not in FORCES]
    for k in others:
        truth = targets["values"][..., k]
        counted = mask * label * jnp.isfinite(truth)
        z = (jnp.nan_to_num(truth) - spec.offsets[k]) / spec.scales[k]
        position = position + _masked_mean((raw[..., layout[spec.targets[k]].start] - z) ** 2, counted) / len(others)
    logit = raw[..., layout["contact"].start]
    contact = jnp.maximum(logit, 0.0) - logit * label + jnp.log1p(jnp.exp(-jnp.abs(logit)))  # BCE with logits, stable
    terms = {"force": force, "contact": _masked_mean(contact, mask), "position": position}
    if not spec.angles:
        return terms | {"angle": jnp.zeros((), raw.dtype)}
    touching = mask * label * jnp.isfinite(targets["theta"]) * jnp.isfinite(targets["phi"])
    theta, phi = jnp.nan_to_num(targets["theta"]), jnp.nan_to_num(targets["phi"])
    if spec.binned:
        angle = 0.0
        for name, bins, truth in (("theta", spec.theta_bins, theta), ("phi", spec.phi_bins, phi)):
            log_p = jax.nn.log_softmax(raw[..., layout[name]], axis=-1)
            angle = angle - jnp.take_along_axis(log_p, calc_bin_index(bins, truth)[..., None], axis=-1)[..., 0]
    else:
        angle = (raw[..., layout["theta"].start] - theta) ** 2 + (raw[..., layout["phi"].start] - phi) ** 2
    return terms | {"angle": _masked_mean(angle, touching)}


def calc_loss(spec: EstimatorSpec, raw, targets: dict, weights: dict | None = None):
    """The weighted sum of :func:`calc_loss_terms`, and the terms."""
    weights = DEFAULT_WEIGHTS | (weights or {})
    terms = calc_loss_terms(spec, raw, targets)
    return sum(weights[name] * value for name, value in terms.items()), terms


def calc_arc_length(theta_1, phi_1, theta_2, phi_2, radius):
    """The great-circle distance between two contact directions on a sphere of
    `radius` (the paper's Eq. 2 as a dot product of unit vectors, with the papers'
    angles: n = (cos θ sin φ, −sin θ, cos θ cos φ)). Eq. 2 as printed,
    R acos(sin φ1 sin φ2 + cos φ1 cos φ2 cos(θ1 − θ2)), is this with θ and φ
    exchanged: θ is the latitude here, φ the longitude."""
    def unit(theta, phi):
        return jnp.stack([jnp.cos(theta) * jnp.sin(phi), -jnp.sin(theta), jnp.cos(theta) * jnp.cos(phi)], axis=-1)

    cosine = jnp.clip(jnp.sum(unit(theta_1, phi_1) * unit(theta_2, phi_2), axis=-1), -1.0, 1.0)
    return radius * jnp.arccos(cosine)


def calc_table_metrics(spec: EstimatorSpec, raw, targets: dict, radius: float | None = None) -> dict:
    """Table I of the paper on the samples that count: RMSE of each force target (N)
    over all of them, of each position and depth target (m) and of θ and φ (rad) over
    the contact samples with labels, the contact BCE, and (with the sensor's `radius`)
    the mean arc-length error (m) over contact samples. NaN where no sample counts."""
    mask = targets["mask"].astype(raw.dtype)
    out = decode_estimator_outputs(spec, raw)
    metrics = {}
    for k, name in enumerate(spec.targets):
        truth = targets["values"][..., k]
        counted = mask if name in FORCES else mask * targets["contact"].astype(raw.dtype) * jnp.isfinite(truth)
        metrics[f"{name}_rmse"] = _masked_rms(out[name] - jnp.nan_to_num(truth), counted)
    metrics["contact_bce"] = calc_loss_terms(spec, raw, targets)["contact"]
    if spec.angles:
        touching = mask * targets["contact"].astype(raw.dtype) * jnp.isfinite(targets["theta"]) * jnp.isfinite(targets["phi"])
        theta, phi = jnp.nan_to_num(targets["theta"]), jnp.nan_to_num(targets["phi"])
        metrics["theta_rmse"] = _masked_rms(out["theta"] - theta, touching)
        metrics["phi_rmse"] = _masked_rms(out["phi"] - phi, touching)
        if radius is not None:
            mean = _masked_mean(calc_arc_length(theta, phi, out["theta"], out["phi"], radius), touching)
            metrics["arc_length_mean"] = jnp.where(jnp.sum(touching) > 0, mean, jnp.nan)
    return metrics
