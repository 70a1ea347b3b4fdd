"""The response table of a stage rig: the sensor's unit responses over a grid of the
probe tip's x, y and height (host to build, pure to read).

A stage presses an upright probe at a few sites, each press a line in height, so a
fit of stage logs needs the response at every (x, y, height) the rig's bounds allow:
computed once per sensor, probe and grid (the simulator's cache keeps it), then read
off by multilinear interpolation (:func:`calc_rig_inputs`), which is differentiable
in the offsets, the home and the lag that the fit moves.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import HydrotactError


class RigTable(eqx.Module):
    """Unit responses (per pascal of E) on a regular grid: `origin` (3,) the first
    node's tip x, y and height (m), `step` (3,) the spacing (m; 1 on an axis of one
    node), `values` (Nx, Ny, Nh, C + 3) the taxel pressures (Pa/Pa) then the force
    on the sensor (N/Pa) at each node."""

    origin: Float[Array, " 3"]
    step: Float[Array, " 3"]
    values: Float[Array, "nx ny nh k"]


def _axis(low: float, high: float, step: float) -> np.ndarray:
    count = max(1, math.ceil((high - low) / step - 1e-9) + 1) if high > low else 1
    return low + step * np.arange(count)


def make_rig_table(model, probe, x_range, y_range, height_range, xy_step: float, height_step: float, *, progress: bool = False) -> RigTable:
    """The table over x in `x_range`, y in `y_range` and tip heights in
    `height_range` (sensor frame, m; the probe upright), `xy_step` and `height_step`
    apart (the last node at or past each range's end). Its top layer is raised to
    above the skin, so that a height above the table reads no contact, and the
    lowest must touch. Poses are simulated through
    :func:`~hydrotact.sim.compute_pose_responses` (cached, resumable)."""
    from ._host import compute_pose_responses

    top = float(np.max(np.asarray(model.field.vertices)[:, 2]))
    low, high = float(height_range[0]), float(height_range[1])
    if low >= top:
        raise HydrotactError(f"rig: the probe's tip never goes below {1e3 * low:g} mm, above the skin's top at {1e3 * top:g} mm: the logs' presses never touch (check the rig's home)")
    high = min(max(high, low + height_step), top + height_step)
    xs, ys, hs = _axis(*x_range, xy_step), _axis(*y_range, xy_step), _axis(low, high, height_step)
    if hs[-1] < top:
        hs = np.append(hs, hs[-1] + height_step)
    grid = np.stack(np.meshgrid(xs, ys, hs, indexing="ij"), axis=-1).reshape(-1, 3)
    rows = np.column_stack([grid, np.zeros_like(grid)])
    unit = compute_pose_responses(model, probe, rows, progress=progress)
    values = np.column_stack([np.asarray(unit.taxel_pressures), np.asarray(unit.force_S)])
    values = values.reshape(len(xs), len(ys), len(hs), -1)
    steps = [float(axis[1] - axis[0]) if len(axis) > 1 else 1.0 for axis in (xs, ys, hs)]
    return RigTable(origin=jnp.asarray([xs[0], ys[0], hs[0]]), step=jnp.asarray(steps), values=jnp.asarray(values))


def calc_rig_inputs(table: RigTable, xy, heights, columns=None):
    """(T, K) the table's responses at the tips' (T, 2) `xy` and (T,) `heights` (m),
    multilinear between nodes and held at the edges; `columns` picks K of its
    C + 3 columns (default: all)."""
    coordinates = [(xy[:, 0] - table.origin[0]) / table.step[0], (xy[:, 1] - table.origin[1]) / table.step[1], (heights - table.origin[2]) / table.step[2]]
    values = table.values if columns is None else table.values[..., jnp.asarray(columns)]
    read = lambda grid: jax.scipy.ndimage.map_coordinates(grid, coordinates, order=1, mode="nearest")
    return jax.vmap(read, in_axes=-1, out_axes=-1)(values)
