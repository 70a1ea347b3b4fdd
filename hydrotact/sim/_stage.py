"""Stage sessions: a sensor pressed at a grid of sites by a positioning stage, logged
as real calibration rigs log it (host).

The rig a lumped fit is meant for has no model of the skin and no probe pose: a
2-axis stage moves the probe to a site (`stage_x`, `stage_y`, never during a press),
a third axis drives it towards the skin (`indentation`, the stage's travel from its
home, whose zero is *not* where the contact starts), and the barometers are read by a
microcontroller. :func:`simulate_stage_log` simulates such a session with the full
forward model and then gives it what real logs have (all seen in public recordings):

- sampling at ~16 Hz with a jittered clock (7-20 ms) and gaps of 15-20 s;
- optionally, the stage's position as a real rig logs it: read on the
  microcontroller's clock and reported in whole motor steps, while the PC stamps
  the time on receipt (`stamp_jitter_s`, `travel_step`), so that the logged speed
  swings from sample to sample along a steady ramp;
- optionally, presses without a hold (`hold_range` (0, 0): the stage turns at its
  deepest point);
- the pressures lagging the logged stage position (~0.05 s);
- an unknown contact onset that differs per press (the skin's height under each
  site) and between sessions (the travel's zero moves);
- per-channel baseline drift of hundreds of Pa to several kPa over a file;
- readings clipped at the part's upper limit (an overloaded channel);
- a channel that does not respond (a dead barometer).

It returns the log and the truth (onsets, lag, drift, which samples are clipped), so
that fits can be measured against it. It is the stand-in for real logs, which the
project does not ship.
"""

import dataclasses
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from ..data import BarometerLog
from ..visco import Prony
from ._log import simulate_log
from ._model import make_sensor_model
from ._trajectory import make_trajectory

FINGERTIP_SENSOR = Path(__file__).parent / "data" / "fingertip4.json"
"""The stand-in's fingertip: the sphere8 elastomer with 4 barometers on risers just
under the pressed area (a sensor JSON file; see its description)."""


DRIFT_PERIOD_S = 300.0  # s: the drift's slow wave has a period of 0.5-1.5 x this, or of the log if longer


def make_site_grid(rows: int = 4, cols: int = 5, pitch: float = 1e-3, center=(0.0, 0.0)) -> np.ndarray:
    """(rows * cols, 2) stage positions (m) on a grid `pitch` apart, row by row."""
    y, x = np.meshgrid((np.arange(rows) - (rows - 1) / 2) * pitch, (np.arange(cols) - (cols - 1) / 2) * pitch, indexing="ij")
    return np.column_stack([x.ravel() + center[0], y.ravel() + center[1]])


@dataclasses.dataclass(frozen=True)
class StageSession:
    """What a stage session does and how its hardware departs from an ideal one.

    **The presses** (one per site, in order): `sites` (S, 2) stage positions, m
    (default: a 4 x 5 grid 1 mm apart, :func:`make_site_grid`); `depth_range` the
    indentation past the contact onset, drawn per press, m; `hold_range` the hold, s;
    `speed` of the approach and retract, m/s; `rest_range` the no-load time between
    presses, s (the stage moves to the next site halfway through); `lead` no-load
    time at the start and end, s; `clearance` of the stage's home above the highest
    contact onset, m; `home_spread` the standard deviation of the home between
    sessions, m (the `indentation` column's zero); `slope_x` the stage's tilt: the tip's
    height at travel 0 rises by slope_x per metre of stage x (0: level).

    **The logging**: `rate_hz` the nominal rate; `jitter_s` the clock jitter (the
    standard deviation of a step), drawn in this range; `num_gaps` gaps of
    `gap_range` s with no samples; `lag_s` how far the pressures lag the logged stage;
    `stamp_jitter_s` the standard deviation of the delay between a sample and its
    time stamp (the PC's receipt; 0: none), s; `travel_step` the resolution the stage
    reports its travel in (a motor step; 0: exact), m.

    **The barometers**: `noise_rms` Pa; `drift_range` each channel's baseline drift
    over the file (a linear trend plus a slow wave of a period of minutes), Pa;
    `overload` a channel whose baseline sits so near the part's upper limit that its
    largest press clips there, 40 % of its rise past the limit (None: none); `silent` channels that do not respond; `seed` of every draw.
    """

    sites: tuple = ()
    depth_range: tuple[float, float] = (0.4e-3, 0.8e-3)
    hold_range: tuple[float, float] = (5.0, 20.0)
    speed: float = 1e-3
    rest_range: tuple[float, float] = (0.1, 3.0)
    lead: float = 3.0
    clearance: float = 0.3e-3
    home_spread: float = 0.1e-3
    slope_x: float = 0.0
    rate_hz: float = 16.0
    jitter_s: tuple[float, float] = (0.007, 0.020)
    num_gaps: int = 1
    gap_range: tuple[float, float] = (15.0, 20.0)
    lag_s: float = 0.05
    stamp_jitter_s: float = 0.0
    travel_step: float = 0.0
    noise_rms: float = 2.0
    drift_range: tuple[float, float] = (300.0, 3000.0)
    overload: str | None = None
    silent: tuple[str, ...] = ()
    seed: int = 0

    def site_positions(self) -> np.ndarray:
        sites = make_site_grid() if len(self.sites) == 0 else np.asarray(self.sites, dtype=np.float64)
        if sites.ndim != 2 or sites.shape[1] != 2 or len(sites) == 0:
            raise HydrotactError(f"stage session: sites must be (S, 2) stage positions in m, got shape {sites.shape}")
        return sites


def find_contact_heights(model, probe, sites_xy, iterations: int = 30) -> np.ndarray:
    """The height of the probe's tip (R's origin, upright) at which it first touches
    the skin above each site: bisection on whether the contact surface has area.

    **Returns:** (S,) z in frame S, m.
    """
    from ..contact import Capacity, make_pose

    sites_xy = np.asarray(sites_xy, dtype=np.float64)
    top = float(np.max(np.asarray(model.field.vertices)[:, 2]))
    bottom = float(np.min(np.asarray(model.field.vertices)[:, 2]))
    high = np.full(len(sites_xy), top + 1e-4)
    low = np.full(len(sites_xy), bottom + 0.25 * (top - bottom))
    capacity = Capacity()

    def touching(z):
        # A polygon found is contact even when a buffer overflowed (the pieces that fit
        # are real), so only a pose that overflowed and found none is in doubt: the
        # buffers grow for those alone. The deep first poses touch at once in the
        # default buffers, and the bisection near the skin fits in them: one
        # compilation, where sizing the buffers to the deepest contact took five.
        nonlocal capacity
        X = jax.vmap(make_pose)(jnp.asarray(np.column_stack([sites_xy, z])))
        while True:
            hit, overflow, needed = (np.asarray(a) for a in _touching(model.field, probe, capacity, model.clusters, X))
            doubt = overflow & ~hit
            if not doubt.any():
                return hit
            capacity = capacity.grown_to(needed[doubt])

    at_low, at_high = touching(low), touching(high)
    if not np.all(at_low) or np.any(at_high):
        bad = int(np.flatnonzero(~at_low | at_high)[0])
        raise HydrotactError(f"stage session: site {bad + 1} at ({1e3 * sites_xy[bad, 0]:g}, {1e3 * sites_xy[bad, 1]:g}) mm is not above the skin")
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        hit = touching(middle)
        low, high = np.where(hit, middle, low), np.where(hit, high, middle)
    return 0.5 * (low + high)


@eqx.filter_jit
def _touching(field, probe, capacity, clusters, poses):
    """Whether the probe touches the skin at each pose, whether a buffer overflowed,
    and what each needed (compiled once per shapes and capacity, not once per call
    of :func:`find_contact_heights`)."""
    from ..contact import calc_contact_surface, map_over_poses

    def one(X):
        surface = calc_contact_surface(field, probe, X, capacity, clusters)
        return surface.total_area > 0.0, surface.did_overflow, surface.needed

    return map_over_poses(one, poses)


def _stage_plan(session: StageSession, onsets_travel: np.ndarray, rng, rate_hz: float):
    """The stage's motion on the simulation clock: times, travel, site index per
    sample, and per press (site, onset travel, deepest travel, start, end)."""
    pieces_t, pieces_travel, pieces_site = [], [], []
    now = 0.0
    presses = []

    def append(travels, site):
        nonlocal now
        pieces_t.append(now + np.arange(len(travels)) / rate_hz)
        pieces_travel.append(travels)
        pieces_site.append(np.full(len(travels), site))
        now += len(travels) / rate_hz

    def hold(duration, travel, site):
        append(np.full(max(1, int(np.ceil(duration * rate_hz))), travel), site)

    def ramp(start, end, site):
        append(np.linspace(start, end, max(2, int(np.ceil(abs(end - start) / session.speed * rate_hz))), endpoint=False), site)

    hold(session.lead, 0.0, 0)
    num_sites = len(onsets_travel)
    for site in range(num_sites):
        depth = rng.uniform(*session.depth_range)
        deepest = onsets_travel[site] + depth
        start = now
        ramp(0.0, deepest, site)
        hold(rng.uniform(*session.hold_range), deepest, site)
        ramp(deepest, 0.0, site)
        presses.append({"site": site, "onset_travel_m": float(onsets_travel[site]), "depth_m": float(depth), "start_s": start, "end_s": now})
        rest = rng.uniform(*session.rest_range) if site + 1 < num_sites else session.lead
        hold(0.5 * rest, 0.0, site)
        hold(0.5 * rest, 0.0, min(site + 1, num_sites - 1))
    return np.concatenate(pieces_t), np.concatenate(pieces_travel), np.concatenate(pieces_site), presses


def _log_clock(session: StageSession, end: float, rng) -> np.ndarray:
    """Jittered sample times in [lag, end], with the gaps cut out."""
    step = 1.0 / session.rate_hz
    jitter = rng.uniform(*session.jitter_s)
    count = int(np.ceil(1.2 * end / step)) + 16
    steps = np.clip(step + jitter * rng.standard_normal(count), 0.25 * step, None)
    times = session.lag_s + np.cumsum(steps)
    times = times[times <= end]
    for _ in range(session.num_gaps):
        length = rng.uniform(*session.gap_range)
        if end - length < 2 * session.lead + 10.0:
            break
        start = rng.uniform(session.lead + 5.0, end - length - 5.0)
        times = times[(times < start) | (times > start + length)]
    return times


def simulate_stage_log(
    sensor, probe, material: Prony, session: StageSession = StageSession(), *, num_rays: int = 64, sim_rate_hz: float = 40.0,
    offset_spread: float = 500.0, progress: bool = False,
) -> tuple[BarometerLog, dict]:
    """Simulate a stage session's log (see the module's docstring): `sensor` a spec
    or built-in name, `probe` a probe or its spec string, pressed upright.

    The elastomer pressures are simulated on a clock of `sim_rate_hz` (the hereditary
    integral included), then read at the log's jittered times (linear interpolation;
    at 1 mm/s and 40 Hz the ramps are sampled every 25 um) and turned into absolute
    readings: the part's ambient pressure, a drawn offset per channel (`offset_spread`
    Pa), the drift, the noise, clipping at the part's upper limit.

    **Returns:** (the log: columns `time`, the channels (absolute Pa), `indentation`
    (the stage's travel towards the skin, m), `stage_x`, `stage_y` (m); the truth: a
    dict with `presses` (per press: site, onset and deepest travel, start and end,
    s), `sites` (S, 2) m, `contact_z_m` (S,) the probe tip's height at first touch,
    `lag_s`, `home_offset_m`, `home_m` (the tip's height at travel 0 over stage x =
    0), `slope_x`, `drift` (T, C) Pa, `baseline_pa` (C,), `elastic`
    (simulation times, (T', C) elastomer pressures, 0 on silent channels), `clipped`
    (T, C) bool, `silent`, `overload`, `material`, `channels`).
    """
    from ..contact import parse_probe
    from ..sensors import SensorSpec, load_sensor

    spec = sensor if isinstance(sensor, SensorSpec) else load_sensor(sensor)
    probe_spec = probe if isinstance(probe, str) else probe.spec
    probe = parse_probe(probe) if isinstance(probe, str) else probe
    channels = list(spec.taxel_names)
    for name in (*session.silent, *([session.overload] if session.overload else [])):
        if name not in channels:
            raise HydrotactError(f"stage session: no channel {name!r} on sensor {spec.name} (has {', '.join(channels)})")
    rng = np.random.default_rng(session.seed)
    sites = session.site_positions()
    model = make_sensor_model(spec, num_rays=num_rays)
    contact_z = find_contact_heights(model, probe, sites)
    home_offset = max(session.home_spread * rng.standard_normal(), 0.2 * session.clearance - session.clearance)  # never at the skin
    rise = session.slope_x * sites[:, 0]  # a tilted stage: the height at travel 0 over each site, above the home
    home = float(np.max(contact_z - rise)) + session.clearance + home_offset
    onsets = home + rise - contact_z  # the travel at which each site's contact starts
    times, travel, site_of, presses = _stage_plan(session, onsets, rng, sim_rate_hz)
    translations = np.column_stack([sites[site_of], home + rise[site_of] - travel])
    trajectory = make_trajectory(times, translations, source="stage session")
    log, _ = simulate_log(spec, probe, trajectory, material, num_rays=num_rays, progress=progress)
    elastic = log.channels  # elastomer pressure on the simulation clock
    elastic[:, np.isin(channels, session.silent)] = 0.0  # dead barometers
    baseline = spec.part.ambient_pa + offset_spread * rng.standard_normal(len(channels))
    # The log's clock; the pressures are those lag_s earlier than the stage it logs.
    clock = _log_clock(session, float(times[-1]), rng)
    observed = np.column_stack([np.interp(clock - session.lag_s, times, elastic[:, c]) for c in range(len(channels))])
    rises = observed.max(axis=0)
    observed = baseline + observed + session.noise_rms * rng.standard_normal(observed.shape)
    span = clock[-1] - clock[0]
    amplitude = rng.uniform(*session.drift_range, size=len(channels)) * rng.choice([-1.0, 1.0], size=len(channels))
    period = rng.uniform(0.5, 1.5, size=len(channels)) * max(span, DRIFT_PERIOD_S)  # thermal drifts take minutes, however long the log
    phase = rng.uniform(0.0, 2 * np.pi, size=len(channels))
    fraction = (clock - clock[0])[:, None] / span
    drift = amplitude * (0.7 * fraction + 0.3 * np.sin(2 * np.pi * (clock - clock[0])[:, None] / period + phase) - 0.3 * np.sin(phase))
    observed = observed + drift
    upper = float(spec.part.range_pa[1])
    if session.overload is not None:  # the highest reading 40 % of the largest press's rise past the limit
        c = channels.index(session.overload)
        shift = upper - float(np.max(observed[:, c])) + 0.4 * rises[c]
        observed[:, c] += shift
        baseline[c] += shift
    clipped = observed >= upper
    observed = np.minimum(observed, upper)
    index = np.clip(np.searchsorted(times, clock, side="right") - 1, 0, len(times) - 1)
    stage_travel = np.interp(clock, times, travel)
    if session.travel_step > 0.0:
        stage_travel = session.travel_step * np.round(stage_travel / session.travel_step)
    stamps = clock
    if session.stamp_jitter_s > 0.0:  # received late by a varying delay, in order
        stamps = np.maximum.accumulate(clock + session.stamp_jitter_s * np.abs(rng.standard_normal(len(clock))))
        stamps = stamps + 1e-9 * np.arange(len(stamps))  # strictly increasing where two delays tie
    columns = {"time": stamps, **{name: observed[:, c] for c, name in enumerate(channels)}}
    columns.update({"indentation": stage_travel, "stage_x": sites[site_of[index], 0], "stage_y": sites[site_of[index], 1]})
    metadata = {key: value for key, value in log.metadata.items() if key not in ("barometer", "field", "num_rays")}
    metadata["rate_hz"] = float(session.rate_hz)
    metadata["probe"] = probe_spec
    metadata["pressure"] = "absolute"
    truth = {
        "presses": presses,
        "sites": sites,
        "contact_z_m": contact_z,
        "lag_s": float(session.lag_s),
        "home_offset_m": float(home_offset),
        "home_m": home,
        "slope_x": float(session.slope_x),
        "drift": drift,
        "baseline_pa": baseline,
        "elastic": (times, elastic),
        "clipped": clipped,
        "silent": tuple(session.silent),
        "overload": session.overload,
        "material": material,
        "channels": tuple(channels),
    }
    return BarometerLog(metadata=metadata, columns=columns), truth
