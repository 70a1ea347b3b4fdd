"""What a synthetic dataset is made of: the data-collection regime of the barometric
estimation paper, as numbers a user can change (host).

The paper's regime (its section IV): about 2500 contact events over three hours at
randomly chosen places on the skin, read at 100 Hz, normal force 0-8 N with low forces
over-sampled, shear up to ±3 N, each event held 0.5-5 s. Our choices where it says
nothing are named here with their reasons.
"""

import dataclasses
import math

import numpy as np

from .._errors import HydrotactError

FORCE_DISTRIBUTIONS = ("loguniform", "uniform")
"""How an event's target force (along its approach: what the gantry controls) is
drawn from `force_range`: `loguniform` (the default: as many events in 0.05-0.5 N as
in 0.5-5 N, so low forces are over-sampled) or `uniform`."""

TARGETS = ("force", "depth")
"""What an event's hold is drawn as: `force` (the default), a target force along the
approach (the force the gantry's load cell controls, drawn by `force_distribution`
from `force_range`, the hold depth found from the simulated force), or `depth`, the
barometric estimation paper's own regime: a depth past the skin point drawn uniformly
from `depth_range`, the forces following (uniform depths over-sample low forces: a
rounded probe's force grows about like depth squared). Force is the default because a
dataset's forces are then the estimator's range whatever the material and wherever on
the skin: with depths, a stiffer material, or a press where the elastomer is thin,
moves the forces (on sphere8 one depth gives forces a tenfold apart over the skin),
and the paper gives its depths only as "roughly 0-8 N"."""

REGIMES = ("gantry", "stage")
"""Where and how events press: `gantry` (the default, the barometric estimation
paper's: points uniform by area over the whole touchable skin, each approach along the
inward skin normal tilted by up to `max_tilt_deg`), or `stage` (a pressing stage over a
strip or pad, as in stage logs: straight down along the sensor's −z, at points uniform
by area over the skin faces that face up (outward normal within 8° of +z), within
`stage_x_range` and `stage_y_range` where given; no tilt)."""

STAGE_FACE_COS = float(np.cos(np.radians(8.0)))
"""A skin face faces up (the stage regime presses it) when its outward normal's z is at
least this (within 8° of +z: a moulded strip's flat skin, not its rounded edges)."""

PHASES = {"gap": 0, "approach": 1, "hold": 2, "retract": 3}
"""The `phase` label's codes: no contact between events, approach, hold, retract."""


@dataclasses.dataclass(frozen=True)
class DatasetConfig:
    """The regime of one synthetic dataset (every field is in the manifest).

    **Events:** `events` how many (the paper's 2500); `seed` of every draw (events,
    material, sensor variation, noise); `probe` the indenter's spec (a 3 mm sphere by
    default; any library probe); `target` what each hold is drawn as (:data:`TARGETS`:
    "force", the default, or "depth", the paper's); `force_distribution` and
    `force_range` (N) of the target force along the approach (what the gantry's load
    cell controls); `depth_range` (m) of the uniformly drawn target depth past the
    skin point (at the default's 2 mm the 3 mm sphere's median hold force over
    sphere8's skin was 7 N at the default 10 MPa, near the paper's 8 N; it spreads
    5-21 N over the skin, thin rubber near the board the stiffest);
    `max_tilt_deg` the largest angle between the approach and the inward skin normal
    (drawn uniformly over the cone's solid angle, so shear spans what a tilted press
    gives); `speed_range` (m/s) of the approach and the retract
    (one speed per event: the retract retraces the approach's poses, so a press costs
    one distinct pose per approach sample plus its hold); `hold_range` and `gap_range`
    (s) the hold and the no-contact time before each event; `clearance` (m) where the
    approach starts, above the skin point; an approach goes no deeper than
    `max_depth` (m) nor than `max_depth_fraction` of the elastomer's thickness along
    its line (an event whose target force is not reached by then holds there, and is
    counted in the manifest); `rate_hz` the sample rate.

    **The rig:** `regime` (:data:`REGIMES`): "gantry" (the paper's, above) or
    "stage" (straight-down presses over the up-facing skin, `max_tilt_deg` unused);
    `stage_x_range`, `stage_y_range` (m, frame S; None: the whole skin) where a stage's
    presses may land.

    **The sensor:** `num_rays` per receptive field; `noise_rms` the barometer noise
    (None: the part's); `gain_spread`, `offset_spread` (Pa) the channels' gains and
    offsets drawn per dataset; `position_jitter` (m) the standard deviation of each
    barometer's position per axis, drawn per dataset (a casting never puts them exactly
    where the drawing does); `randomise_material` draws the material from the
    material document's covariance (domain randomisation) instead of using its values.

    **The files:** `shard_rows` rows per Parquet shard; `test_fraction` of the
    `split_blocks` contiguous blocks of events held out for testing.
    """

    events: int = 2500
    seed: int = 0
    probe: str = "sphere:r=3mm"
    target: str = "force"
    depth_range: tuple[float, float] = (0.1e-3, 2e-3)
    force_distribution: str = "loguniform"
    force_range: tuple[float, float] = (0.05, 8.0)
    max_tilt_deg: float = 30.0
    speed_range: tuple[float, float] = (4e-3, 20e-3)
    hold_range: tuple[float, float] = (0.5, 5.0)
    gap_range: tuple[float, float] = (0.5, 2.0)
    clearance: float = 0.3e-3
    max_depth: float = 6e-3
    max_depth_fraction: float = 0.5
    rate_hz: float = 100.0
    num_rays: int = 64
    noise_rms: float | None = None
    gain_spread: float = 0.0
    offset_spread: float = 0.0
    position_jitter: float = 0.0
    randomise_material: bool = False
    shard_rows: int = 100_000
    test_fraction: float = 0.3
    split_blocks: int = 10
    regime: str = "gantry"
    stage_x_range: tuple[float, float] | None = None
    stage_y_range: tuple[float, float] | None = None

    def __post_init__(self):
        check_config(self)

    def to_json(self) -> dict:
        return {field.name: (list(value) if isinstance(value := getattr(self, field.name), tuple) else value) for field in dataclasses.fields(self)}

    @classmethod
    def from_json(cls, document: dict) -> "DatasetConfig":
        names = {field.name for field in dataclasses.fields(cls)}
        return cls(**{key: (tuple(value) if isinstance(value, list) else value) for key, value in document.items() if key in names})


OPTIONS = {"rate_hz": "--rate", "num_rays": "--rays"}  # fields whose command-line option is not their name


def _option(name: str) -> str:
    return OPTIONS.get(name, "--" + name.replace("_", "-"))


def _check_range(config, name: str, low_limit: float, high_limit: float = math.inf, unit: str = "") -> None:
    values = getattr(config, name)
    try:
        low, high = (float(v) for v in values)
    except (TypeError, ValueError):
        raise HydrotactError(f"{_option(name)}: expected two numbers LOW,HIGH, got {values!r}") from None
    if not (np.isfinite(low) and np.isfinite(high)) or not low_limit <= low <= high <= high_limit:
        span = f"within {low_limit:g}-{high_limit:g} {unit}" if np.isfinite(high_limit) else f"at least {low_limit:g} {unit}"
        raise HydrotactError(f"{_option(name)}: {low:g},{high:g} must be LOW <= HIGH, {span}".rstrip())


def check_config(config: DatasetConfig) -> None:
    """One clear message, naming the command-line option, for an impossible regime."""
    def whole(name, low, high=None):
        value = getattr(config, name)
        if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < low or (high is not None and value > high):
            bound = f"{low}-{high}" if high is not None else f"at least {low}"
            raise HydrotactError(f"{_option(name)}: must be a whole number {bound}, got {value!r}")

    whole("events", 1, 1_000_000)
    whole("seed", 0)
    whole("num_rays", 1, 4096)
    whole("shard_rows", 100)
    whole("split_blocks", 2)
    if config.regime not in REGIMES:
        raise HydrotactError(f"--regime: {config.regime!r} is not one of {', '.join(REGIMES)}")
    for name in ("stage_x_range", "stage_y_range"):
        if getattr(config, name) is not None:
            if config.regime != "stage":
                raise HydrotactError(f"{_option(name)}: only a stage presses within a range (--regime stage)")
            _check_range(config, name, -1.0, 1.0, "m")
    if config.target not in TARGETS:
        raise HydrotactError(f"--target: {config.target!r} is not one of {', '.join(TARGETS)}")
    _check_range(config, "depth_range", 0.0, 0.05, "m")
    if config.target == "depth" and config.depth_range[1] <= 0.0:
        raise HydrotactError("--depth-range: the deepest target must lie past the skin (HIGH > 0 m)")
    if config.force_distribution not in FORCE_DISTRIBUTIONS:
        raise HydrotactError(f"--force-distribution: {config.force_distribution!r} is not one of {', '.join(FORCE_DISTRIBUTIONS)}")
    _check_range(config, "force_range", 0.0, 100.0, "N")
    if config.force_distribution == "loguniform" and config.force_range[0] <= 0.0:
        raise HydrotactError("--force-range: a log-uniform force needs LOW > 0 N")
    _check_range(config, "speed_range", 1e-5, 1.0, "m/s")
    _check_range(config, "hold_range", 0.0, 3600.0, "s")
    _check_range(config, "gap_range", 0.0, 3600.0, "s")
    checks = (
        ("max_tilt_deg", 0.0, 80.0, "deg"),
        ("clearance", 0.0, 0.05, "m"),
        ("max_depth", 1e-5, 0.05, "m"),
        ("max_depth_fraction", 0.01, 1.0, ""),
        ("rate_hz", 1.0, 10_000.0, "Hz"),
        ("gain_spread", 0.0, 0.25, ""),
        ("offset_spread", 0.0, 1e5, "Pa"),
        ("position_jitter", 0.0, 1e-3, "m"),
        ("test_fraction", 0.0, 0.9, ""),
    )
    for name, low, high, unit in checks:
        value = float(getattr(config, name))
        if not np.isfinite(value) or not low <= value <= high:
            raise HydrotactError(f"{_option(name)}: {value:g} is outside {low:g}-{high:g} {unit}".rstrip())
    if config.noise_rms is not None and (not np.isfinite(float(config.noise_rms)) or not 0.0 <= float(config.noise_rms) <= 1e4):
        raise HydrotactError(f"--noise: {float(config.noise_rms):g} Pa is outside 0-10000 Pa")
    if config.speed_range[0] / config.rate_hz > config.max_depth:
        raise HydrotactError(f"--speed-range: {config.speed_range[0]:g} m/s moves more than --max-depth ({config.max_depth:g} m) in one sample at {config.rate_hz:g} Hz")
