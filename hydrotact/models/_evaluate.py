"""Using a trained estimator: batched predictions over recordings, streaming one sample
at a time (as on the microcontroller), and the paper's evaluation (Table I metrics,
the arc-length error, contact detection and its latency).

A recording is run as one sequence from the zero state, as the estimator runs on the
sensor: no windows. Batched and streaming predictions apply the same step function
(:func:`calc_estimator_step`), the first through `lax.scan`, the second one call per
sample.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._bins import BIN_WIDTH
from ._estimator import FORCES, calc_estimator_sequence, calc_estimator_step, decode_estimator_outputs, make_initial_state
from ._loss import calc_arc_length, calc_table_metrics
from ._sequences import target_labels

CONTACT_FORCE = 0.1
"""N: the contact flag's threshold on |F| (the datasets' label), also used to turn a
predicted force into a contact detector."""


def _decoded(spec, raw) -> dict:
    return {name: np.asarray(value) for name, value in decode_estimator_outputs(spec, raw).items() if name != "force"}


def predict_recording(trained, readings) -> dict:
    """Estimates for a recording `readings` (T, channels) in Pa, in the model's channel
    order, from the zero state: its regression targets (fx, fy, fz, fn in N by
    default; x, y, depth in m), theta, phi (rad; sensors with contact angles),
    contact_probability; each (T,)."""
    inputs = jnp.asarray(trained.normaliser(np.asarray(readings, dtype=np.float64)), dtype=jnp.float32)
    _, raw = _run(trained.spec, trained.params, inputs)
    return _decoded(trained.spec, raw)


@functools.lru_cache(maxsize=32)
def _sequence_function(spec):
    return jax.jit(lambda params, inputs: calc_estimator_sequence(spec, params, inputs))


def _run(spec, params, inputs):
    return _sequence_function(spec)(params, inputs)


class StreamingEstimator:
    """The estimator one sample at a time: `update(reading)` (channels,) in Pa returns
    the estimates for that sample (a dict of floats), carrying the hidden state;
    `reset()` returns to the zero state. The same numbers as :func:`predict_recording`."""

    def __init__(self, trained):
        self.trained = trained
        spec = trained.spec
        self._step = jax.jit(lambda params, state, x: calc_estimator_step(spec, params, state, x))
        self.reset()

    def reset(self) -> None:
        self.state = make_initial_state(self.trained.spec, jnp.float32)

    def update(self, reading) -> dict:
        x = jnp.asarray(self.trained.normaliser(np.asarray(reading, dtype=np.float64)), dtype=jnp.float32)
        self.state, raw = self._step(self.trained.params, self.state, x)
        return {name: float(value) for name, value in _decoded(self.trained.spec, raw).items()}


def _edges(flag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    change = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    return np.flatnonzero(change == 1), np.flatnonzero(change == -1)  # first contact sample, first sample after


def calc_detection(truth: np.ndarray, detected: np.ndarray, rate_hz: float) -> dict:
    """A contact detector against the contact flag: accuracy, precision, recall, and
    the latency (s) at onset and release (median and 95th percentile over the true
    contacts: from the true edge to the detector's first agreeing sample within that
    contact, or within the gap that follows a release)."""
    truth, detected = np.asarray(truth, bool), np.asarray(detected, bool)
    true_on, true_off = _edges(truth)
    onset, release = [], []
    for start, stop in zip(true_on, true_off):
        hit = np.flatnonzero(detected[start:stop])
        if hit.size:
            onset.append(hit[0] / rate_hz)
        following = np.searchsorted(true_on, stop)
        end = true_on[following] if following < len(true_on) else len(truth)
        quiet = np.flatnonzero(~detected[stop:end])
        if quiet.size:
            release.append(quiet[0] / rate_hz)
    positives = detected.sum()

    def stats(values):
        if not values:
            return {"median_s": float("nan"), "p95_s": float("nan"), "count": 0}
        return {"median_s": float(np.median(values)), "p95_s": float(np.percentile(values, 95)), "count": len(values)}

    return {
        "accuracy": float(np.mean(truth == detected)),
        "precision": float((truth & detected).sum() / positives) if positives else float("nan"),
        "recall": float((truth & detected).sum() / truth.sum()) if truth.any() else float("nan"),
        "missed_contacts": int(len(true_on) - len(onset)),
        "onset_latency": stats(onset),
        "release_latency": stats(release),
    }


def evaluate_estimator(trained, blocks: list, rate_hz: float, radius: float | None = None) -> dict:
    """The paper's evaluation over recordings (`blocks`: dicts of columns, each run
    from the zero state, every sample counted): Table I's metrics (RMSE of each
    regression target: forces in N over every sample, positions and depth in m over
    contact samples; of theta and phi in rad over contact samples; contact BCE), the
    mean arc-length error (m, with the sensor's `radius`), and the contact detectors
    (the predicted probability above 0.5; with fx, fy, fz among the targets, the
    predicted |F| above :data:`CONTACT_FORCE`).
    Returns {"metrics", "detection", "predictions" (per block), "location_errors"
    (over the contact samples, for :func:`calc_error_map`; None on a sensor without
    angles)}."""
    spec = trained.spec
    raws, predictions, targets = [], [], []
    for number, block in enumerate(blocks):
        readings = np.column_stack([block[name] for name in trained.channels])
        inputs = jnp.asarray(trained.normaliser(readings), dtype=jnp.float32)
        _, raw = _run(spec, trained.params, inputs)
        raws.append(raw)
        predictions.append(_decoded(spec, raw))
        count = len(readings)
        targets.append({
            "values": target_labels(block, spec.targets, f"recording {number + 1}").astype(np.float32),
            "theta": np.asarray(block.get("theta", np.full(count, np.nan)), np.float32),
            "phi": np.asarray(block.get("phi", np.full(count, np.nan)), np.float32),
            "contact": np.asarray(block["contact"], np.float32),
            "mask": np.ones(count, np.float32),
        })
    joined = {name: jnp.asarray(np.concatenate([t[name] for t in targets])) for name in targets[0]}
    metrics = {name: float(value) for name, value in calc_table_metrics(spec, jnp.concatenate(raws), joined, radius).items()}
    truth = np.concatenate([t["contact"] for t in targets]) > 0
    probability = np.concatenate([p["contact_probability"] for p in predictions])
    detection = {"contact_head": calc_detection(truth, probability > 0.5, rate_hz)}
    if all(name in spec.targets for name in FORCES[:3]):
        magnitude = np.linalg.norm(np.column_stack([np.concatenate([p[name] for p in predictions]) for name in FORCES[:3]]), axis=1)
        detection["force_threshold"] = calc_detection(truth, magnitude > CONTACT_FORCE, rate_hz)
    return {"metrics": metrics, "detection": detection, "predictions": predictions, "location_errors": _location_errors(spec, targets, predictions, radius)}


def _location_errors(spec, targets, predictions, radius) -> dict | None:
    """Over the contact samples with angles (as Table I's angle metrics): the true θ,
    φ (rad) and the distance to the estimate, the arc length of Eq. 2 (m) on a sphere
    of `radius`, else the angle between the two contact directions (rad)."""
    if not spec.angles:
        return None
    theta, phi = (np.concatenate([t[name] for t in targets]).astype(np.float64) for name in ("theta", "phi"))
    estimate = {name: np.concatenate([p[name] for p in predictions]).astype(np.float64) for name in ("theta", "phi")}
    touching = (np.concatenate([t["contact"] for t in targets]) > 0) & np.isfinite(theta) & np.isfinite(phi)
    theta, phi = theta[touching], phi[touching]
    error = np.asarray(calc_arc_length(theta, phi, estimate["theta"][touching], estimate["phi"][touching], 1.0 if radius is None else radius))
    return {"theta": theta, "phi": phi, "error": error, "unit": "rad" if radius is None else "m"}


def calc_error_map(location_errors: dict, theta_range, phi_range, width: float = BIN_WIDTH) -> dict:
    """The paper's Fig. 5: the mean localisation error over the skin, in cells of
    `width` (rad, π/16 as the angle bins) over the sensor's θ and φ ranges, by the
    true contact angles (`location_errors` from :func:`evaluate_estimator`). Returns
    {"theta_edges" (A+1,), "phi_edges" (B+1,), "mean" (A, B) NaN where no contact fell,
    "count" (A, B), "clamped", "unit"}. A contact labelled beyond a range counts in
    the edge cell nearest to it, and "clamped" says how many did: the labels are the
    centre of pressure's angles, which a tilted press near the edge can put a few
    degrees past it (2 % of the contact samples, up to 5 deg, in a 600-event sphere8
    dataset). So the cells together give the mean over every contact, as Table I's
    arc length does."""
    edges = [np.linspace(low, high, max(1, int(np.ceil((high - low) / width - 1e-9))) + 1) for low, high in (theta_range, phi_range)]
    raw = (np.asarray(location_errors["theta"]), np.asarray(location_errors["phi"]))
    samples = tuple(np.clip(angles, edge[0], edge[-1]) for angles, edge in zip(raw, edges))
    count, _, _ = np.histogram2d(*samples, bins=edges)
    total, _, _ = np.histogram2d(*samples, bins=edges, weights=np.asarray(location_errors["error"]))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
    return {"theta_edges": edges[0], "phi_edges": edges[1], "mean": mean, "count": count.astype(int),
            "clamped": int(np.sum((samples[0] != raw[0]) | (samples[1] != raw[1]))), "unit": location_errors["unit"]}


def calc_skin_radius(sensor, tolerance: float = 0.01) -> float | None:
    """The radius (m) of a sensor whose touchable skin lies on a sphere about its
    contact centre (sphere8: 10 mm), else None: the arc-length error of the paper's
    Eq. 2 is a distance on a sphere. A spread of the corners' distances beyond
    `tolerance` of their mean (an ellipsoid, a pad) is no sphere."""
    from ..datasets import find_touchable_skin

    if sensor.contact_center_S is None:
        return None
    corners = find_touchable_skin(sensor, sensor.make_mesh(check=False)).corners.reshape(-1, 3)
    distances = np.linalg.norm(corners - np.asarray(sensor.contact_center_S), axis=1)
    mean = float(distances.mean())
    return mean if float(np.ptp(distances)) <= tolerance * mean else None
