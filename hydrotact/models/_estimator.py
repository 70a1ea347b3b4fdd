"""The contact estimators: a two-layer GRU (ours), the paper's one-layer tanh RNN, and
MLPs, each with binned or plain angle heads (pure JAX; parameters a plain pytree).

An estimator reads one sample of the barometers (normalised per channel) per step and
outputs, per step, one vector laid out as :attr:`EstimatorSpec.outputs` says: its
regression targets (:attr:`EstimatorSpec.targets`; by default Fx, Fy, Fz, Fn in N, the
paper's; any of :data:`REGRESSION_TARGETS`: also the contact position x, y along a strip
or pad and the indentation depth, in m); then, on a sensor with contact angles, θ and
φ (two values, rad) or their bin logits (binned); then the contact logit. A force is
output in N as it is; a position or depth as a z-score of the training split's contact
samples (its offset and scale are part of the spec), so that a millimetre and a newton
weigh alike in the loss whatever a sensor's size. The recurrent ones
carry a hidden state per layer from step to step; the MLP sees the current sample only.

The published models (barometric estimation paper, from the authors' repository), in
this module's terms, with their parameter counts on sphere8 / ellipsoid8 (paper's bins):

| model | architecture | hidden | parameters |
|---|---|---|---:|
| Binned RNN | rnn | (48,) | 4205 / 3960 |
| RNN | rnn | (48,) | 3127 |
| Binned MLP | mlp | (12, 24, 64) | 3905 / 3580 |
| MLP | mlp | (12, 64, 64) | 5555 |

Ours by default: a two-layer GRU with binned heads, its two layers as wide as the
microcontroller budget of 6000 parameters allows (22 units, 5815 parameters on sphere8
with bins covering the whole ranges); `hidden=(18, 18)` (4115) matches the Binned
RNN's count.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ._bins import AngleBins, decode_bins, make_angle_bins
from ._cells import calc_gru_step, calc_linear, calc_rnn_step, init_linear, init_recurrent

ARCHITECTURES = ("gru", "rnn", "mlp")
PARAMETER_BUDGET = 6000
"""The most parameters an estimator may have (the sensor's microcontroller)."""

DEFAULT_HIDDEN = {("rnn", True): (48,), ("rnn", False): (48,), ("mlp", True): (12, 24, 64), ("mlp", False): (12, 64, 64)}
"""The paper's hidden sizes; the GRU's default is sized to the budget (two equal layers)."""
FORCES = ("fx", "fy", "fz", "fn")
POSITIONS = ("x", "y", "depth")
REGRESSION_TARGETS = FORCES + POSITIONS
"""What an estimator may regress: the force on the sensor in S (`fx`, `fy`, `fz`) and
along the inward skin normal (`fn`), N, on every sample (0 without contact); the
contact position in S (`x`, `y`: the centre of pressure, or a stage's probe position
on a flat strip or pad) and the indentation `depth` past the skin, m, on contact
samples only (undefined without contact)."""
LABEL_COLUMNS = {"fx": ("fx",), "fy": ("fy",), "fz": ("fz",), "fn": ("fn",), "x": ("cop_x", "contact_x"), "y": ("cop_y", "contact_y"), "depth": ("depth",)}
"""Where each target's label is read: a dataset's column (`cop_x`, ...), else a log's
(`contact_x`, ...), the first present."""


def label_column(target: str, columns) -> str | None:
    """The column of `columns` (names) holding `target`'s label, or None."""
    return next((name for name in LABEL_COLUMNS[target] if name in columns), None)


@dataclasses.dataclass(frozen=True)
class EstimatorSpec:
    """What an estimator is (static, hashable): `architecture` ("gru", "rnn", "mlp"),
    `hidden` sizes (one per recurrent layer, or the MLP's hidden layers),
    `num_inputs` (barometers), `angles` (whether the sensor has θ, φ), the
    angle bins (`theta_bins`, `phi_bins`: AngleBins for binned heads, None for plain),
    the regression `targets` (names from :data:`REGRESSION_TARGETS`, in output order)
    and each one's `target_offsets` and `target_scales` (a target is output as
    (value - offset) / scale; empty: 0 and 1 for every target, values as they are)."""

    architecture: str
    hidden: tuple
    num_inputs: int
    angles: bool = True
    theta_bins: AngleBins | None = None
    phi_bins: AngleBins | None = None
    targets: tuple = FORCES
    target_offsets: tuple = ()
    target_scales: tuple = ()

    def __post_init__(self):
        if self.architecture not in ARCHITECTURES:
            raise ValueError(f"architecture must be one of {', '.join(ARCHITECTURES)}, got {self.architecture!r}")
        if not self.hidden or any(int(h) < 1 for h in self.hidden) or self.num_inputs < 1:
            raise ValueError(f"hidden sizes and inputs must be positive, got {self.hidden!r}, {self.num_inputs!r}")
        if (self.theta_bins is None) != (self.phi_bins is None) or (self.theta_bins is not None and not self.angles):
            raise ValueError("binned heads need both θ and φ bins, on a sensor with contact angles")
        check_targets(self.targets)
        for name in ("target_offsets", "target_scales"):
            values = getattr(self, name)
            if values and (len(values) != len(self.targets) or not all(math.isfinite(v) for v in values)):
                raise ValueError(f"{name}: one finite number per target ({len(self.targets)}), got {values!r}")
        if self.target_scales and min(self.target_scales) <= 0.0:
            raise ValueError(f"target_scales must be positive, got {self.target_scales!r}")

    @property
    def offsets(self) -> tuple:
        return self.target_offsets or (0.0,) * len(self.targets)

    @property
    def scales(self) -> tuple:
        return self.target_scales or (1.0,) * len(self.targets)

    @property
    def binned(self) -> bool:
        return self.theta_bins is not None

    @property
    def outputs(self) -> dict:
        """The output vector's layout: name -> slice."""
        sizes = {name: 1 for name in self.targets}
        if self.angles:
            sizes |= {"theta": self.theta_bins.count, "phi": self.phi_bins.count} if self.binned else {"theta": 1, "phi": 1}
        sizes["contact"] = 1
        layout, start = {}, 0
        for name, size in sizes.items():
            layout[name] = slice(start, start + size)
            start += size
        return layout

    @property
    def num_outputs(self) -> int:
        return max(s.stop for s in self.outputs.values())

    @property
    def recurrent(self) -> bool:
        return self.architecture != "mlp"

    def to_json(self) -> dict:
        return {
            "architecture": self.architecture, "hidden": list(self.hidden), "num_inputs": self.num_inputs, "angles": self.angles,
            "theta_bins": None if self.theta_bins is None else self.theta_bins.to_json(),
            "phi_bins": None if self.phi_bins is None else self.phi_bins.to_json(),
            "targets": list(self.targets), "target_offsets": list(self.offsets), "target_scales": list(self.scales),
        }

    @classmethod
    def from_json(cls, document: dict) -> "EstimatorSpec":
        """From :meth:`to_json` (a model saved before targets were configurable regresses the four forces)."""
        bins = lambda entry: None if entry is None else AngleBins(**entry)
        targets = tuple(document.get("targets", FORCES))
        offsets, scales = (tuple(float(v) for v in document.get(key, ())) for key in ("target_offsets", "target_scales"))
        if offsets == (0.0,) * len(targets) and scales == (1.0,) * len(targets):
            offsets = scales = ()
        return cls(document["architecture"], tuple(document["hidden"]), int(document["num_inputs"]), bool(document["angles"]), bins(document["theta_bins"]), bins(document["phi_bins"]),
                   targets, offsets, scales)


def check_targets(targets) -> tuple:
    """`targets` as a tuple of known, distinct regression targets; a ValueError otherwise."""
    targets = tuple(targets)
    unknown = [name for name in targets if name not in REGRESSION_TARGETS]
    if unknown:
        raise ValueError(f"unknown target {unknown[0]!r}: use {', '.join(REGRESSION_TARGETS)}")
    if len(set(targets)) != len(targets):
        raise ValueError(f"a target named twice in {', '.join(targets)}")
    return targets


def calc_target_scaling(arrays: dict, targets, contact=None) -> tuple[tuple, tuple]:
    """Each target's (offsets, scales) from training labels `arrays` (name -> column,
    through :data:`LABEL_COLUMNS`): forces 0 and 1 N (as the paper's); a position or
    depth the mean and standard deviation of its finite labels on contact samples
    (`contact` (N,) flags; a spread under 0.1 mm counts as 0.1 mm). Empty tuples when
    every target is a force."""
    if all(name in FORCES for name in targets):
        return (), ()
    offsets, scales = [], []
    for name in targets:
        if name in FORCES:
            offsets.append(0.0), scales.append(1.0)
            continue
        values = np.asarray(arrays[label_column(name, arrays)], dtype=np.float64)
        counted = np.isfinite(values) & (np.ones(len(values), bool) if contact is None else np.asarray(contact) > 0)
        if not counted.any():
            raise ValueError(f"target {name!r}: no finite label on a contact sample to scale it by")
        offsets.append(float(np.mean(values[counted]))), scales.append(max(float(np.std(values[counted])), 1e-4))
    return tuple(offsets), tuple(scales)


def make_estimator_spec(sensor, architecture: str = "gru", binned: bool = True, hidden=None, cover: str = "whole", targets=FORCES, scaling=((), ())) -> EstimatorSpec:
    """An estimator for a sensor (a :class:`hydrotact.sensors.SensorSpec`): its
    barometers in, the regression `targets` (with their `scaling`, (offsets, scales),
    from :func:`calc_target_scaling`), angle heads over its contact-angle ranges (none
    without them; π/16 bins covering the whole ranges, or the paper's count with
    `cover="floor"`). `hidden` defaults to :data:`DEFAULT_HIDDEN`, and for the GRU to
    the largest two equal layers within :data:`PARAMETER_BUDGET`."""
    angles = sensor.theta_range is not None and sensor.phi_range is not None
    theta_bins = phi_bins = None
    if binned and angles:
        theta_bins, phi_bins = make_angle_bins(*sensor.theta_range, cover=cover), make_angle_bins(*sensor.phi_range, cover=cover)
    targets = check_targets(targets)
    make = lambda sizes: EstimatorSpec(architecture, tuple(int(h) for h in sizes), int(sensor.num_taxels), angles, theta_bins, phi_bins, targets, *scaling)
    if hidden is not None:
        return make(hidden)
    if architecture == "gru":
        size = 1
        while count_parameters(make((size + 1, size + 1))) <= PARAMETER_BUDGET:
            size += 1
        return make((size, size))
    return make(DEFAULT_HIDDEN[(architecture, bool(binned and angles))])


def init_estimator(spec: EstimatorSpec, key, dtype=jnp.float32) -> dict:
    """Fresh parameters: {"layers": [per layer], "head": linear} (see `_cells`)."""
    keys = jax.random.split(key, len(spec.hidden) + 1)
    sizes = (spec.num_inputs, *spec.hidden)
    if spec.recurrent:
        gates = 3 if spec.architecture == "gru" else 1
        layers = [init_recurrent(k, a, b, gates, dtype) for k, a, b in zip(keys, sizes[:-1], sizes[1:])]
    else:
        layers = [init_linear(k, a, b, dtype) for k, a, b in zip(keys, sizes[:-1], sizes[1:])]
    return {"layers": layers, "head": init_linear(keys[-1], sizes[-1], spec.num_outputs, dtype)}


def make_initial_state(spec: EstimatorSpec, dtype=jnp.float32) -> tuple:
    """The hidden state before the first sample: zeros per recurrent layer (() for an MLP)."""
    return tuple(jnp.zeros(h, dtype) for h in spec.hidden) if spec.recurrent else ()


def calc_estimator_step(spec: EstimatorSpec, params: dict, state: tuple, x):
    """One sample (num_inputs,) through the estimator: (new state, raw outputs (num_outputs,))."""
    if spec.recurrent:
        step = calc_gru_step if spec.architecture == "gru" else calc_rnn_step
        new_state, h = [], x
        for layer, previous in zip(params["layers"], state):
            h = step(layer, previous, h)
            new_state.append(h)
        return tuple(new_state), calc_linear(params["head"], h)
    h = x
    for layer in params["layers"]:
        h = jax.nn.relu(calc_linear(layer, h))
    return state, calc_linear(params["head"], h)


def calc_estimator_sequence(spec: EstimatorSpec, params: dict, inputs, state: tuple | None = None):
    """A sequence (T, num_inputs) through the estimator with `lax.scan`, from `state`
    (zeros by default): (final state, raw outputs (T, num_outputs)). vmap it over a batch."""
    state = make_initial_state(spec, inputs.dtype) if state is None else state
    return lax.scan(lambda carry, x: calc_estimator_step(spec, params, carry, x), state, inputs)


def decode_estimator_outputs(spec: EstimatorSpec, raw) -> dict:
    """The estimates from raw outputs (..., num_outputs): each regression target by
    name (N or m), and `force` (..., 4) Fx, Fy, Fz, Fn (N) where all four are targets;
    `theta`, `phi` (rad; Eq. 1 when binned); `contact_probability`."""
    layout = spec.outputs
    out = {"contact_probability": jax.nn.sigmoid(raw[..., layout["contact"].start])}
    for name, offset, scale in zip(spec.targets, spec.offsets, spec.scales):
        value = raw[..., layout[name].start]
        out[name] = value if (offset, scale) == (0.0, 1.0) else value * scale + offset
    if all(name in spec.targets for name in FORCES):
        out["force"] = jnp.stack([out[name] for name in FORCES], axis=-1)
    if spec.angles:
        if spec.binned:
            out["theta"] = decode_bins(spec.theta_bins, raw[..., layout["theta"]])
            out["phi"] = decode_bins(spec.phi_bins, raw[..., layout["phi"]])
        else:
            out["theta"], out["phi"] = raw[..., layout["theta"].start], raw[..., layout["phi"].start]
    return out


def count_parameters(spec: EstimatorSpec) -> int:
    """Trainable parameters (from the shapes; nothing is computed)."""
    shapes = jax.eval_shape(lambda: init_estimator(spec, jax.random.PRNGKey(0)))
    return int(sum(math.prod(leaf.shape) for leaf in jax.tree_util.tree_leaves(shapes)))


def count_macs(spec: EstimatorSpec) -> int:
    """Multiply-accumulates per step of the matrix-vector products (the gates' and
    activations' elementwise work is a few per cent more)."""
    sizes = (spec.num_inputs, *spec.hidden)
    gates = {"gru": 3, "rnn": 1, "mlp": 0}[spec.architecture]
    if spec.recurrent:
        layers = sum(gates * b * (a + b) for a, b in zip(sizes[:-1], sizes[1:]))
    else:
        layers = sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))
    return int(layers + sizes[-1] * spec.num_outputs)


def check_budget(spec: EstimatorSpec, budget: int = PARAMETER_BUDGET) -> int:
    """The parameter count; a ValueError above the microcontroller budget."""
    count = count_parameters(spec)
    if count > budget:
        raise ValueError(f"{spec.architecture} {spec.hidden}: {count} parameters, over the budget of {budget}")
    return count
