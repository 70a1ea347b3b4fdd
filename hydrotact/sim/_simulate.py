"""The one forward model: sensor layout, material, probe and trajectory -> what the
barometers report, the contact wrench and the labels (pure).

Per sample: the contact surface of the probe and the elastomer (unit modulus), what
each barometer reads of it (a ray-cast taxel the skin pressure in its receptive field,
an elastic barometer the stress its tractions cause at its port, by reciprocity), the wrench on the sensor, the contact normal and location.
Everything but the contact flag is linear in E or independent of it, so the unit
response is computed once per pose and the material acts on it: a Prony relaxation
modulus through the hereditary integral (an elastic material is a Prony series with no
terms), a contact pushing but never pulling (visco.calc_contact_response). Optionally
the barometer signal follows: ambient, per-channel gain and offset, drift, noise from a
PRNG key, quantisation to the part's LSB (visco.calc_barometer_readings).

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

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._buffers import AbstractCapacity
from .._math import safe_div, safe_norm
from .._types import Array, Bool, Float, Int
from ..contact import Capacity, Pose, calc_contact_surface, map_over_poses
from ..elastic import calc_elastic_readings
from ..taxel import TaxelCapacity, calc_taxel_pressures
from ..visco import BarometerSignal, Prony, calc_barometer_readings, calc_contact_response
from ._model import SensorModel
from ._trajectory import Trajectory

CONTACT_THRESHOLD_N = 0.1


class UnitResponse(eqx.Module):
    """The response to one probe pose at unit modulus (E = 1 Pa).

    **Fields:** `taxel_pressures` (num_taxels,), `force_S` (3,), `torque_S` (3,) —
    each per pascal of E; `normal_S` (3,) the inward skin normal at the contact (0
    without contact); `contact_point_S` (3,) the centre of pressure, m; `area` m^2;
    `did_overflow` (a buffer was too small: the response is incomplete) and `needed`
    (6,) the entries each buffer of :class:`SimCapacity` needed, for the host to grow
    them (:func:`hydrotact._buffers.run_growing`).
    """

    taxel_pressures: Float[Array, " num_taxels"]
    force_S: Float[Array, " 3"]
    torque_S: Float[Array, " 3"]
    normal_S: Float[Array, " 3"]
    contact_point_S: Float[Array, " 3"]
    area: Float[Array, ""]
    did_overflow: Bool[Array, ""]
    needed: Int[Array, " 6"]


class Samples(eqx.Module):
    """Simulated samples along a trajectory (arrays with a leading sample axis).

    **Fields:** `times` (T,) s; `unit` the UnitResponse per sample; `modulus` the
    material's instantaneous modulus E(0), Pa; `taxel_pressures` (T, num_taxels) Pa,
    the elastomer pressure at each barometer; `readings` (T, num_taxels) the
    barometers' absolute readings, Pa, or None when simulated without a barometer
    signal; `force_S`, `torque_S` (T, 3) N, N m; `normal_force` (T,) N; `theta`,
    `phi` (T,) rad (NaN where undefined); `contact` (T,) bool.
    """

    times: Float[Array, " num_samples"]
    unit: UnitResponse
    modulus: Float[Array, ""]
    taxel_pressures: Float[Array, "num_samples num_taxels"]
    readings: Float[Array, "num_samples num_taxels"] | None
    force_S: Float[Array, "num_samples 3"]
    torque_S: Float[Array, "num_samples 3"]
    normal_force: Float[Array, " num_samples"]
    theta: Float[Array, " num_samples"]
    phi: Float[Array, " num_samples"]
    contact: Bool[Array, " num_samples"]


class SimCapacity(AbstractCapacity):
    """Buffer sizes of a simulation (static: changing one recompiles), in the order of
    :attr:`UnitResponse.needed`: the contact broad phase's `tets`, `others`, `pairs`
    and `polygons` (:class:`hydrotact.contact.Capacity`), then the taxel sampler's
    candidate `taxel_pairs` and its `taxel_pieces` (:class:`hydrotact.taxel.TaxelCapacity`).
    Grown by the one rule of :meth:`hydrotact._buffers.AbstractCapacity.grown_to`.
    """

    purpose: ClassVar[str] = "the simulation"
    advice: ClassVar[str] = "the probe presses too deep, or the contact surface has too many triangles near the taxels"

    tets: int = eqx.field(static=True, default=Capacity().tets)
    others: int = eqx.field(static=True, default=Capacity().others)
    pairs: int = eqx.field(static=True, default=Capacity().pairs)
    polygons: int = eqx.field(static=True, default=Capacity().polygons)
    taxel_pairs: int = eqx.field(static=True, default=TaxelCapacity().pairs)
    taxel_pieces: int = eqx.field(static=True, default=TaxelCapacity().pieces)

    @classmethod
    def of(cls, contact: Capacity = Capacity(), taxel: TaxelCapacity = TaxelCapacity()) -> "SimCapacity":
        """The capacity made of a contact capacity and a taxel capacity."""
        return cls(*contact.sizes, *taxel.sizes)

    @property
    def contact(self) -> Capacity:
        return Capacity(self.tets, self.others, self.pairs, self.polygons)

    @property
    def taxel(self) -> TaxelCapacity:
        return TaxelCapacity(self.taxel_pairs, self.taxel_pieces)


def calc_unit_response(model: SensorModel, probe, X_SR: Pose, capacity: SimCapacity = SimCapacity()) -> UnitResponse:
    """The unit-modulus response of the sensor to the probe at pose X_SR (pure;
    jittable, vmappable over X_SR, differentiable in X_SR, the field and the layout)."""
    surface = calc_contact_surface(model.field, probe, X_SR, capacity.contact, model.clusters)
    if model.uses_rays:
        readings = calc_taxel_pressures(model.layout, surface, model.num_rays, capacity.taxel)
        pressures, taxel_overflow, taxel_needed = readings.pressures, readings.did_overflow, readings.needed
    else:
        dtype = surface.areas.dtype
        pressures = jnp.zeros(model.num_taxels, dtype)
        taxel_overflow, taxel_needed = jnp.asarray(False), jnp.zeros(2, surface.needed.dtype)
    if model.elastic is not None:
        pressures = pressures.at[model.elastic_channels].set(calc_elastic_readings(model.elastic, surface))
    force_on_soft, torque_on_soft = surface.calc_wrench()
    weights = jnp.where(surface.valid, surface.pressure_integrals, 0.0)
    gradients = model.field.calc_tet_pressure_gradients()[jnp.maximum(surface.tet_index, 0)]
    inward = jnp.sum(weights[:, None] * gradients, axis=0)
    inward = safe_div(inward, safe_norm(inward))
    return UnitResponse(
        taxel_pressures=pressures,
        force_S=force_on_soft,
        torque_S=torque_on_soft,
        normal_S=inward,
        contact_point_S=surface.pressure_centroid_S,
        area=surface.total_area,
        did_overflow=surface.did_overflow | taxel_overflow,
        needed=jnp.concatenate([surface.needed, taxel_needed]),
    )


def calc_contact_angles(contact_point_S, contact_center_S):
    """(theta, phi) of a contact point seen from the centre C: n = (p - C) / |p - C|,
    theta = asin(-n_y), phi = atan2(n_x, n_z)."""
    n = contact_point_S - contact_center_S
    n = safe_div(n, safe_norm(n)[..., None])
    theta = jnp.arcsin(jnp.clip(-n[..., 1], -1.0, 1.0))
    phi = jnp.arctan2(n[..., 0], n[..., 2])
    return theta, phi


def calc_samples(model: SensorModel, material: Prony, times, unit: UnitResponse, barometer: BarometerSignal | None = None, key=None) -> Samples:
    """What the sensor reports for unit responses along a trajectory (pure).

    Taxel pressures, force and torque are the hereditary integrals of their unit
    responses with the material's relaxation modulus E(t) (the correspondence
    principle; for a material without Prony terms simply E times the unit response),
    a contact pushing but never pulling (visco.calc_contact_response). With
    `barometer`, the taxel pressures are also turned into absolute readings at the
    sample times (noise from `key` when given, none without).

    **Arguments:** `times` (T,) s, strictly increasing; `unit` a UnitResponse with a
    leading sample axis T; the rest as :func:`calc_simulation`.

    **Returns:** Samples.
    """
    stacked = jnp.concatenate([unit.taxel_pressures, unit.force_S, unit.torque_S], axis=1)
    relaxed = calc_contact_response(material, times, stacked)
    count = unit.taxel_pressures.shape[1]
    taxel_pressures, force, torque = relaxed[:, :count], relaxed[:, count : count + 3], relaxed[:, count + 3 :]
    readings = None if barometer is None else calc_barometer_readings(barometer, times, taxel_pressures, key=key)
    magnitude = safe_norm(force)
    theta, phi = calc_contact_angles(unit.contact_point_S, model.contact_center_S[None])
    defined = (unit.area > 0.0) & jnp.all(jnp.isfinite(model.contact_center_S))
    return Samples(
        times=times,
        unit=unit,
        modulus=material.instantaneous_modulus,
        taxel_pressures=taxel_pressures,
        readings=readings,
        force_S=force,
        torque_S=torque,
        normal_force=jnp.sum(force * unit.normal_S, axis=-1),
        theta=jnp.where(defined, theta, jnp.nan),
        phi=jnp.where(defined, phi, jnp.nan),
        contact=magnitude > CONTACT_THRESHOLD_N,
    )


def calc_simulation(
    model: SensorModel,
    material: Prony,
    probe,
    trajectory: Trajectory,
    capacity: SimCapacity = SimCapacity(),
    barometer: BarometerSignal | None = None,
    key=None,
) -> Samples:
    """Simulate the sensor along a whole trajectory in one pure call.

    Jittable, vmappable over trajectories (of one length) and differentiable with
    respect to the trajectory's translations and rotation vectors, every material
    parameter (E∞, Eᵢ, τᵢ), the model's field and taxel layout (positions, axes,
    receptive-field sizes) and the barometer's gains, offsets and drifts. Quantisation
    passes gradients straight through; the contact flag has none.

    **Arguments:**

    - `model`: the SensorModel (unit-modulus field, clusters, taxel layout).
    - `material`: a visco.Prony; an elastic material is one with no terms
      (`visco.make_prony(E)`).
    - `probe`: the rigid probe (or half-space) pressed into the sensor.
    - `trajectory`: times and probe poses X_SR; the samples are read at its times
      (:func:`hydrotact.sim.resample_trajectory` puts it at a part's rate).
    - `capacity`: buffer sizes (static). A buffer that overflows is flagged in
      `.unit.did_overflow`, never truncated silently: check it, or use
      :func:`hydrotact.sim.simulate`, which grows the buffers and recomputes.
    - `barometer`, `key`: the barometer signal model and the PRNG key of its noise
      (no readings without `barometer`, no noise without `key`).

    **Returns:** Samples (leading axis: the trajectory's samples).
    """
    unit = map_over_poses(lambda X: calc_unit_response(model, probe, X, capacity), trajectory.X_SR)
    return calc_samples(model, material, trajectory.times, unit, barometer, key)
