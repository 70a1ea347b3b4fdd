"""The end-to-end forward model: probe poses -> taxel pressures, wrench and labels.

Per sample: the contact surface of the probe and the elastomer (unit modulus), what
each taxel reads of it, the wrench on the sensor, the contact normal and location.
Everything but the contact flag is linear in E or independent of it, so the unit
response is computed once per trajectory and the material only scales it.

Conventions (frame S, the sensor base frame: PCB on z = 0, +z the pad normal):

- `force_S`, `torque_S` (about S's origin): the wrench the probe exerts on the
  sensor, N and N m.
- `normal_force`: the force along the inward skin normal at the contact, N
  (positive when pressing). The inward normal is the pressure-weighted mean of the
  field gradient over the contact: the strain is 0 on the skin, so its gradient is
  normal to the skin and points inwards.
- contact angles, for sensors that define a centre C: with n the unit vector from C
  to the centre of pressure, theta = asin(-n_y), phi = atan2(n_x, n_z) (the
  barometric estimation paper's convention); NaN without contact or centre.
- `contact`: |force| > 0.1 N (the threshold of that paper's labels).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._math import safe_div, safe_norm
from .._types import Array, Bool, Float, Int
from ..contact import Capacity, Pose, calc_contact_surface, map_over_poses
from ..contact._api import grown_contact_capacity
from ..taxel import calc_taxel_pressures, grown_capacity
from ._model import Material, SensorModel
from ._trajectory import Trajectory

CONTACT_THRESHOLD_N = 0.1


class UnitResponse(eqx.Module):
    """The response to one probe pose at unit modulus (E = 1 Pa).

    **Fields:** `taxel_pressures` (num_taxels,), `force_S` (3,), `torque_S` (3,) —
    each per pascal of E; `normal_S` (3,) the inward skin normal at the contact (0
    without contact); `contact_point_S` (3,) the centre of pressure, m; `area` m^2;
    `contact_overflow`, `taxel_overflow` (a buffer was too small) with
    `contact_needed` (the contact surface's `needed`) and `taxel_needed`, for the
    host to grow them.
    """

    taxel_pressures: Float[Array, " num_taxels"]
    force_S: Float[Array, " 3"]
    torque_S: Float[Array, " 3"]
    normal_S: Float[Array, " 3"]
    contact_point_S: Float[Array, " 3"]
    area: Float[Array, ""]
    contact_overflow: Bool[Array, ""]
    taxel_overflow: Bool[Array, ""]
    contact_needed: Int[Array, "..."]
    taxel_needed: Int[Array, ""]

    @property
    def overflow(self):
        return self.contact_overflow | self.taxel_overflow


class Samples(eqx.Module):
    """Simulated samples along a trajectory (arrays with a leading sample axis).

    **Fields:** `times` (T,) s; `unit` the UnitResponse per sample; `modulus` E, Pa;
    `taxel_pressures` (T, num_taxels) Pa; `force_S`, `torque_S` (T, 3) N, N m;
    `normal_force` (T,) N; `theta`, `phi` (T,) rad (NaN where undefined);
    `contact` (T,) bool.
    """

    times: Float[Array, " num_samples"]
    unit: UnitResponse
    modulus: Float[Array, ""]
    taxel_pressures: Float[Array, "num_samples num_taxels"]
    force_S: Float[Array, "num_samples 3"]
    torque_S: Float[Array, "num_samples 3"]
    normal_force: Float[Array, " num_samples"]
    theta: Float[Array, " num_samples"]
    phi: Float[Array, " num_samples"]
    contact: Bool[Array, " num_samples"]


class SimCapacity(eqx.Module):
    """Buffer sizes of a simulation (static): the contact broad phase's and the
    taxel sampler's candidate pairs."""

    contact: Capacity = eqx.field(static=True, default=Capacity())
    taxel_pairs: int = eqx.field(static=True, default=4096)


def calc_unit_response(model: SensorModel, probe, X_SR: Pose, capacity: SimCapacity = SimCapacity()) -> UnitResponse:
    """The unit-modulus response of the sensor to the probe at pose X_SR (pure;
    jittable, vmappable over X_SR, differentiable in X_SR, the field and the layout)."""
    surface = calc_contact_surface(model.field, probe, X_SR, capacity.contact, model.clusters)
    readings = calc_taxel_pressures(model.layout, surface, model.num_rays, capacity.taxel_pairs)
    force_on_soft, torque_on_soft = surface.calc_wrench()
    weights = jnp.where(surface.valid, surface.pressure_integrals, 0.0)
    gradients = model.field.calc_tet_pressure_gradients()[jnp.maximum(surface.tet_index, 0)]
    inward = jnp.sum(weights[:, None] * gradients, axis=0)
    inward = safe_div(inward, safe_norm(inward))
    return UnitResponse(
        taxel_pressures=readings.pressures,
        force_S=force_on_soft,
        torque_S=torque_on_soft,
        normal_S=inward,
        contact_point_S=surface.pressure_centroid_S,
        area=surface.total_area,
        contact_overflow=surface.overflow,
        taxel_overflow=readings.overflow,
        contact_needed=surface.needed,
        taxel_needed=readings.needed,
    )


def calc_contact_angles(contact_point_S, contact_center_S):
    """(theta, phi) of a contact point seen from the centre C: n = (p - C) / |p - C|,
    theta = asin(-n_y), phi = atan2(n_x, n_z)."""
    n = contact_point_S - contact_center_S
    n = safe_div(n, safe_norm(n)[..., None])
    theta = jnp.arcsin(jnp.clip(-n[..., 1], -1.0, 1.0))
    phi = jnp.arctan2(n[..., 0], n[..., 2])
    return theta, phi


def calc_samples(model: SensorModel, material: Material, times, unit: UnitResponse) -> Samples:
    """Scale unit responses (batched over samples) by the material and derive the
    labels (pure)."""
    modulus = material.modulus
    return _labelled_samples(model, times, unit, modulus, modulus * unit.taxel_pressures, modulus * unit.force_S, modulus * unit.torque_S)


def calc_viscoelastic_samples(model: SensorModel, prony, times, unit: UnitResponse) -> Samples:
    """Samples of a viscoelastic material (pure): taxel pressures, force and torque are
    the hereditary integrals of their unit responses with the Prony modulus E(t)
    (correspondence principle), a contact pushing but never pulling
    (visco.calc_contact_response); `modulus` is reported as E(0)."""
    from ..visco import calc_contact_response

    stacked = jnp.concatenate([unit.taxel_pressures, unit.force_S, unit.torque_S], axis=1)
    relaxed = calc_contact_response(prony, times, stacked)
    count = unit.taxel_pressures.shape[1]
    return _labelled_samples(model, times, unit, prony.instantaneous_modulus, relaxed[:, :count], relaxed[:, count : count + 3], relaxed[:, count + 3 :])


def _labelled_samples(model, times, unit, modulus, taxel_pressures, force, torque) -> Samples:
    magnitude = safe_norm(force)
    in_contact = magnitude > CONTACT_THRESHOLD_N
    theta, phi = calc_contact_angles(unit.contact_point_S, model.contact_center_S[None])
    defined = (unit.area > 0.0) & jnp.all(jnp.isfinite(model.contact_center_S))
    return Samples(
        times=times,
        unit=unit,
        modulus=modulus,
        taxel_pressures=taxel_pressures,
        force_S=force,
        torque_S=torque,
        normal_force=jnp.sum(force * unit.normal_S, axis=-1),
        theta=jnp.where(defined, theta, jnp.nan),
        phi=jnp.where(defined, phi, jnp.nan),
        contact=in_contact,
    )


def calc_simulation(model: SensorModel, material: Material, probe, trajectory: Trajectory, capacity: SimCapacity = SimCapacity()) -> Samples:
    """Simulate a whole trajectory in one pure call (vmap over samples): for jit,
    grad and vmap over trajectories. Check `.unit.overflow`, or use :func:`simulate`."""
    unit = jax.vmap(calc_unit_response, in_axes=(None, None, 0, None))(model, probe, trajectory.X_SR, capacity)
    return calc_samples(model, material, trajectory.times, unit)


@eqx.filter_jit
def _chunk_response(model, probe, X_SR, capacity):
    return map_over_poses(lambda X: calc_unit_response(model, probe, X, capacity), X_SR)


def grown_sim_capacity(capacity: SimCapacity, unit: UnitResponse) -> SimCapacity:
    """A capacity that holds what the overflowing samples of `unit` needed (host)."""
    contact, taxel_pairs = capacity.contact, capacity.taxel_pairs
    contact_overflow, taxel_overflow = np.asarray(unit.contact_overflow), np.asarray(unit.taxel_overflow)
    if contact_overflow.any():
        contact = grown_contact_capacity(contact, np.asarray(unit.contact_needed)[contact_overflow])
    if taxel_overflow.any():
        taxel_pairs = grown_capacity(taxel_pairs, np.asarray(unit.taxel_needed)[taxel_overflow])
    return SimCapacity(contact=contact, taxel_pairs=taxel_pairs)


def compute_unit_responses(model: SensorModel, probe, X_SR: Pose, capacity: SimCapacity | None = None, chunk: int = 128, progress: bool = False):
    """Unit responses for a batch of poses, in jitted chunks of `chunk` poses, growing
    buffers (and recomputing the chunk) whenever one overflows (host).

    **Returns:** (UnitResponse with a leading sample axis, as NumPy arrays; the
    capacity that sufficed).
    """
    capacity = capacity or SimCapacity()
    count = X_SR.translation.shape[0]
    chunk = max(1, min(chunk, count))
    pieces = []
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=count, unit="sample", desc=f"simulating {model.name}", leave=False)
    for start in range(0, count, chunk):
        index = np.minimum(np.arange(start, start + chunk), count - 1)  # pad the last chunk
        poses = jax.tree_util.tree_map(lambda a: a[index], X_SR)
        while True:
            unit = _chunk_response(model, probe, poses, capacity)
            if not bool(np.any(np.asarray(unit.overflow))):
                break
            capacity = grown_sim_capacity(capacity, unit)
        used = min(chunk, count - start)
        pieces.append(jax.tree_util.tree_map(lambda a: np.asarray(a)[:used], unit))
        if bar is not None:
            bar.update(used)
    if bar is not None:
        bar.close()
    unit = jax.tree_util.tree_map(lambda *parts: np.concatenate(parts), *pieces)
    return unit, capacity


def simulate(model: SensorModel, material: Material, probe, trajectory: Trajectory, capacity: SimCapacity | None = None, progress: bool = False) -> Samples:
    """Simulate the sensor along a probe trajectory (host entry point: chunks,
    buffer growth, optional progress bar). **Returns:** Samples (NumPy-backed)."""
    unit, _ = compute_unit_responses(model, probe, trajectory.X_SR, capacity, progress=progress)
    return scale_unit_responses(model, material, trajectory.times, unit)


def scale_unit_responses(model: SensorModel, material, times, unit: UnitResponse) -> Samples:
    """:func:`calc_samples` (a Material) or :func:`calc_viscoelastic_samples` (a
    visco.Prony) on host (NumPy) unit responses; **Returns:** NumPy-backed Samples."""
    unit = jax.tree_util.tree_map(jnp.asarray, unit)
    if isinstance(material, Material):
        samples = calc_samples(model, material, jnp.asarray(times), unit)
    else:
        samples = calc_viscoelastic_samples(model, material, jnp.asarray(times), unit)
    return jax.tree_util.tree_map(np.asarray, samples)
