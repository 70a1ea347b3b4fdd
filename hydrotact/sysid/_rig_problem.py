"""Stage logs in a simulator fit: the rig's parameters and the inputs they give
(pure, but for :func:`make_rig_arrays`, host).

A stage log has no probe pose; a rig (:class:`hydrotact.data.Rig`) makes one: the
tip at (stage x + offset_x, stage y + offset_y, home + slope_x · stage x −
travel(t − lag)), pressed upright (slope_x where the rig has one: a stage not level
with the skin). The unit responses then depend on those parameters, so the fit reads them
off the rig's response table (:func:`hydrotact.sim.calc_rig_inputs`) at every step
instead of once. Each fitted parameter lives in x as u, its value centre + half ·
tanh(u): always inside its bounds (the table covers them), smooth across them.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._types import Array, Float, Int
from ..sim import RigTable, calc_rig_inputs

BOUND_FRACTION = 0.98  # a rig parameter within 2 % of its range from a bound is at the bound: not identified


class RigArrays(eqx.Module):
    """The rig's part of a fit problem: the response `table`; per log the stage's
    `stage_xy` (T, 2) and `travel` (T,) (m) and the table `columns` its inputs read
    (its channels, then its fitted force columns); every rig parameter's `centre`
    and `half` range (P,) in the order of `names` (offset_x, offset_y, home[k] per
    log, lag_s, then slope_x[k] per log where the rig has a slope; half 0 where
    fixed)."""

    table: RigTable
    stage_xy: tuple[Float[Array, "num_samples 2"], ...]
    travel: tuple[Float[Array, " num_samples"], ...]
    columns: tuple[Int[Array, " num_inputs"], ...]
    centre: Float[Array, " num_rig"]
    half: Float[Array, " num_rig"]
    names: tuple[str, ...] = eqx.field(static=True)
    setup: tuple = eqx.field(static=True, default=())  # (key, value) pairs: what a comparison needs to place the probe again

    def setup_document(self) -> dict:
        """The rig as the fit used it (SI; bounds per parameter): report.json's
        `rig_setup`, which `compare` reads back."""
        return {key: (dict(value) if isinstance(value, tuple) else value) for key, value in self.setup}

    @property
    def free(self) -> tuple[int, ...]:
        return tuple(int(k) for k in np.flatnonzero(np.asarray(self.half) > 0.0))


def rig_parameter_names(num_logs: int, sloped: bool = False) -> tuple[str, ...]:
    slopes = [f"slope_x[{k + 1}]" for k in range(num_logs)] if sloped else []
    return ("offset_x", "offset_y", *[f"home[{k + 1}]" for k in range(num_logs)], "lag_s", *slopes)


def rig_values(rig: RigArrays, free: tuple[int, ...], u):
    """(P,) every rig parameter's value (m, s) from the fitted ones' u."""
    full = jnp.zeros(rig.centre.shape, u.dtype)
    if free:
        full = full.at[jnp.asarray(free)].set(u)
    return rig.centre + rig.half * jnp.tanh(full)


def rig_start(rig: RigArrays, free: tuple[int, ...], starts) -> np.ndarray:
    """The u of the fitted parameters for their `starts` (P,) (clipped inside the
    bounds: a start on a bound would be an infinite u)."""
    centre, half = np.asarray(rig.centre), np.asarray(rig.half)
    index = list(free)
    return np.arctanh(np.clip((np.asarray(starts)[index] - centre[index]) / half[index], -0.999, 0.999))


def calc_stage_inputs(table: RigTable, times, tips_xy, travel, home, lag, columns):
    """(T, K) unit responses of a stage log: the tips at `tips_xy` (T, 2) (the stage
    moved by the offsets) and at `home` (a scalar, or (T,) where the rig has a slope)
    less the travel read `lag` s before each sample (the pressures lag the logged
    travel), off the rig's `table`."""
    lagged = jnp.interp(times - lag, times, travel)
    return calc_rig_inputs(table, tips_xy, home - lagged, columns)


def rig_log_inputs(rig: RigArrays, values, log: int, times):
    """(T, K) unit responses of log `log` at the rig parameters `values`."""
    num_logs = len(rig.travel)
    offset = values[:2]
    home, lag = values[2 + log], values[2 + num_logs]
    if len(rig.names) > 3 + num_logs:  # sloped: the height at travel 0 follows the stage's x
        home = home + values[3 + num_logs + log] * rig.stage_xy[log][:, 0]
    return calc_stage_inputs(rig.table, times, rig.stage_xy[log] + offset[None, :], rig.travel[log], home, lag, rig.columns[log])


def make_rig_arrays(rig, model, probe, logs, sources, columns, progress: bool = False, drift="none", saturation_pa=None) -> tuple[RigArrays, np.ndarray]:
    """The RigArrays of `logs` (host; `columns` per log the table columns each reads)
    and every rig parameter's start (P,): builds the response table over the
    stages' sites moved by the offsets' bounds and the heights the homes' bounds
    and the travels reach."""
    from ..sim import make_rig_table

    stage_xy, travel = [], []
    for log, source in zip(logs, sources):
        xy, moved = rig.stage_columns(log, source)
        stage_xy.append(xy)
        travel.append(moved)
    slopes = [] if rig.slope_x is None else [rig.slope_x] * len(logs)
    parameters = [rig.offset_x, rig.offset_y, *[rig.home] * len(logs), rig.lag_s, *slopes]
    all_xy = np.concatenate(stage_xy)
    x_range = (float(all_xy[:, 0].min()) + rig.offset_x.low, float(all_xy[:, 0].max()) + rig.offset_x.high)
    y_range = (float(all_xy[:, 1].min()) + rig.offset_y.low, float(all_xy[:, 1].max()) + rig.offset_y.high)
    deepest = max(max(float(np.max(t)) for t in travel), rig.max_travel or 0.0)  # a held-out log may press deeper
    shallowest = min(float(np.min(t)) for t in travel)
    rise = np.zeros(1)  # the slope's reach: slope_x · stage x at the stage's extremes and the slope's bounds
    if rig.slope_x is not None:
        rise = np.outer([rig.slope_x.low, rig.slope_x.high], [all_xy[:, 0].min(), all_xy[:, 0].max()]).ravel()
    height_range = (rig.home.low + float(rise.min()) - deepest, rig.home.high + float(rise.max()) - shallowest)
    poses = (int(np.ceil((x_range[1] - x_range[0]) / rig.xy_step)) + 1) * (int(np.ceil((y_range[1] - y_range[0]) / rig.xy_step)) + 1)
    poses *= int(np.ceil((height_range[1] - height_range[0]) / rig.height_step)) + 1
    if poses > 2_000_000:
        raise HydrotactError(
            f"{rig.source}: the response table would hold {poses:,} poses (x {1e3 * x_range[0]:g} to {1e3 * x_range[1]:g} mm, "
            f"y {1e3 * y_range[0]:g} to {1e3 * y_range[1]:g} mm, heights {1e3 * height_range[0]:g} to {1e3 * height_range[1]:g} mm): "
            "narrow the offsets' and home's bounds, or raise table_step"
        )
    table = make_rig_table(model, probe, x_range, y_range, height_range, rig.xy_step, rig.height_step, progress=progress)
    centre = np.asarray([0.5 * (p.low + p.high) for p in parameters])
    half = np.asarray([0.5 * (p.high - p.low) for p in parameters])
    arrays = RigArrays(
        table=table,
        stage_xy=tuple(jnp.asarray(xy) for xy in stage_xy),
        travel=tuple(jnp.asarray(t) for t in travel),
        columns=tuple(jnp.asarray(c) for c in columns),
        centre=jnp.asarray(centre),
        half=jnp.asarray(half),
        names=rig_parameter_names(len(logs), sloped=rig.slope_x is not None),
        setup=(
            ("name", rig.name), ("probe", rig.probe), ("columns", tuple(sorted(rig.columns.items()))), ("drift", drift), ("saturation_pa", saturation_pa),
            ("bounds", tuple((name, (p.low, p.high)) for name, p in (("offset_x", rig.offset_x), ("offset_y", rig.offset_y), ("home", rig.home), ("lag_s", rig.lag_s),
                                                                     *([("slope_x", rig.slope_x)] if rig.slope_x is not None else [])))),
            ("table_step", (("xy", rig.xy_step), ("height", rig.height_step))),
        ),
    )
    return arrays, np.asarray([p.start for p in parameters])
