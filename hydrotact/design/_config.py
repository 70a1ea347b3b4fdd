"""What a layout design is asked for and what it returns: the settings
(`DesignConfig`), a layout's scores (`LayoutScore`) and the result (`LayoutDesign`),
and how the CLI names each objective (host)."""

import dataclasses

import numpy as np

from .._errors import HydrotactError
from ._feasible import Placement
from ._objective import DesignObjective

OBJECTIVE_DESCRIPTIONS = {
    DesignObjective.D: "D-optimal (mean log det of the Fisher information of contact point and force)",
    DesignObjective.A: "A-optimal (mean Cramer-Rao bound on the localisation error)",
    DesignObjective.K: "learned (mean leave-one-out localisation error of a nearest-neighbour estimator)",
}
OBJECTIVE_SCORES = {
    DesignObjective.D: "the mean log det, higher is better",
    DesignObjective.A: "minus the mean squared bound, mm^2, higher is better",
    DesignObjective.K: "minus the balance-norm of the components' mean squared errors, mm^2, higher is better",
}
"""What each objective's score is (the CLI's report)."""


@dataclasses.dataclass(frozen=True)
class DesignConfig:
    """How a layout is designed (every field is written into the result).

    **Objective:** `objective` "k" (learned, the default: the localisation error of a
    nearest-neighbour estimator learned from the contacts' readings, which ranked
    trained estimators' errors where the bounds did not; see :mod:`._objective`), "d"
    (D-optimal) or "a" (A-optimal, the localisation bound); `balance` for "k": the p
    of the p-norm over the target's components (θ and φ, or x, y, z) of their mean
    squared errors, 1 summing them and a larger one leaning on the worst, so that one
    angle is not bought with the other (on sphere8 the summed and the balanced
    designs trained to the same errors within their spreads); `contacts` drawn for the
    design (a pool: for "d" and "a" each step's gradient is over a fresh minibatch of
    `batch` of them, and every `eval_every` steps the whole pool is scored, the best
    layout so far kept; a design fitted to a few fixed contacts fits them, not the
    skin: measured on sphere8 with 24, the designed layout gained 4.4 on its contacts
    and lost 2.2 against the built-in on held-out ones; "k" uses the whole pool every
    step, each contact the others' neighbour) and as many again held out;
    `num_rays` per receptive field; the noise (:class:`NoiseModel`): `noise_rms` (Pa,
    None: the part's), `noise_floor` (Pa) for a cast barometer's drift, creep and
    hysteresis (our choice, not measured on real logs) and `relative_noise` the part
    proportional to a reading (an estimator knows a cast barometer's gain to a few per
    cent).

    **Constraints:** `placement` "inside" or "board" (None: where the sensor's own
    ports are), `margin` and `spacing` (m), `max_tilt_deg` of an axis from +z,
    `max_height` the highest a port may sit above the board (m; risers; None: anywhere
    inside);
    `field_sizes` also designs each receptive field's size (else the sensor's).

    **Search:** `restarts` random feasible starts (besides the sensor's own layout),
    `steps` of Adam each, moving a port by up to `learning_rate` mm per step and an
    axis (or a cone's half-angle) by `axis_learning_rate` rad (the score is more
    sensitive to a barometer's direction than to its place: on sphere8 a step of
    0.03 rad on every axis moves it about as much as 0.3 mm on every port),
    both decaying to a tenth along a cosine; stopping early after `patience` steps
    without a gain; `seed` of every draw.

    **Elastic barometers** (:mod:`._elastic`): the steps are split into `expansions`
    rounds, each on the readings linearised at its start (the fields' derivatives,
    three solves per barometer), moving no port further than `trust_radius` (m); the
    layout a round reaches is solved exactly and kept only if it scores better (else
    the radius halves).
    """

    objective: str = "k"
    balance: float = 4.0
    contacts: int = 192
    batch: int = 32
    eval_every: int = 10
    num_rays: int = 32
    relative_noise: float = 0.05
    noise_floor: float = 20.0
    noise_rms: float | None = None
    placement: str | None = None
    margin: float = 1e-3
    spacing: float = 2.5e-3
    max_tilt_deg: float = 75.0
    max_height: float | None = None
    field_sizes: bool = False
    restarts: int = 3
    steps: int = 120
    learning_rate: float = 0.2
    axis_learning_rate: float = 0.02
    patience: int = 25
    seed: int = 0
    expansions: int = 3
    trust_radius: float = 1e-3

    def __post_init__(self):
        DesignObjective.parse(self.objective, "objective")
        if self.placement is not None:
            Placement.parse(self.placement, "placement")
        for name, low in (("contacts", 3), ("batch", 1), ("eval_every", 1), ("num_rays", 1), ("restarts", 0), ("steps", 0), ("patience", 1), ("expansions", 1)):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < low:
                raise HydrotactError(f"--{name.replace('_', '-')}: must be a whole number of at least {low}, got {value!r}")
        for name in ("relative_noise", "noise_floor", "learning_rate", "axis_learning_rate"):
            value = float(getattr(self, name))
            rate = name.endswith("learning_rate")
            if not np.isfinite(value) or value < 0.0 or (rate and value == 0.0):
                raise HydrotactError(f"--{name.replace('_', '-')}: must be a {'positive' if rate else 'non-negative'} number, got {value!r}")
        if isinstance(self.balance, bool) or not isinstance(self.balance, int | float | np.floating) or not (np.isfinite(self.balance) and self.balance >= 1.0):
            raise HydrotactError(f"--balance: must be a number of at least 1 (1 sums the target's components' errors), got {self.balance!r}")
        if isinstance(self.trust_radius, bool) or not isinstance(self.trust_radius, int | float | np.floating) or not (np.isfinite(self.trust_radius) and 1e-6 <= self.trust_radius <= 0.05):
            raise HydrotactError(f"--trust-radius: must be a length in m within 1e-6-0.05, got {self.trust_radius!r}")
        if self.noise_rms is not None and not (np.isfinite(self.noise_rms) and self.noise_rms >= 0.0):
            raise HydrotactError(f"--noise: must be a non-negative pressure in Pa, got {self.noise_rms!r}")
        if self.max_height is not None and (isinstance(self.max_height, bool) or not isinstance(self.max_height, int | float | np.floating) or not np.isfinite(self.max_height)):
            raise HydrotactError(f"--max-height: must be a height above the board in m, got {self.max_height!r}")

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class LayoutScore:
    """A layout's `score` on the design's contacts and `held_out_score` on the held-out
    ones (higher is better; the design's objective), its `localisation_bounds` (m, per
    held-out contact: the Cramér–Rao bound) and their root mean square `rms_bound`
    (m), and its `neighbour_errors` (m, per held-out contact: a nearest-neighbour
    estimator's, learned from the other held-out contacts) and their root mean square
    `rms_neighbour_error` (m); both error models whatever the objective."""

    score: float
    held_out_score: float
    localisation_bounds: np.ndarray
    rms_bound: float
    neighbour_errors: np.ndarray
    rms_neighbour_error: float


@dataclasses.dataclass(frozen=True)
class LayoutDesign:
    """The result of :func:`design_layout`.

    **Fields:** `spec` the sensor with the designed layout; `start_spec` the sensor as
    given; `config`, `regime` (the DatasetConfig the contacts follow); `designed`,
    `builtin` (None when the counts differ) and `random` (the random starts, before
    optimisation) :class:`LayoutScore`\\ s; `compared` the scores of the layouts passed
    as `compare`, by name; `histories` the pool's score as (step, score) rows for each
    start (`start_names` name them, `start_layouts` gives each start's (positions,
    axes)); `held_out_points_S` (N, 3) the held-out contacts' skin points (for maps);
    `elapsed_s`.
    """

    spec: object
    start_spec: object
    config: DesignConfig
    regime: object
    designed: LayoutScore
    builtin: LayoutScore | None
    random: list
    histories: list
    start_names: list
    start_layouts: list
    compared: dict
    held_out_points_S: np.ndarray
    elapsed_s: float
