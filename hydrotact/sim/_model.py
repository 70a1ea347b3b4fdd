"""The device-side model of a sensor: its unit-modulus pressure field, tet clusters
for the contact search, and its taxel layout; and the material that scales it."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._types import Array, Float
from ..contact import TetClusters, make_tet_clusters
from ..field import PressureField, calc_distance_field, make_laplace_problem, make_pressure_field, solve_strain
from ..taxel import TaxelLayout, make_taxel_layout

FIELD_KINDS = ("laplace", "distance")


class SensorModel(eqx.Module):
    """A sensor ready to simulate (a pytree, built once on the host).

    The pressure field has unit modulus (E = 1 Pa, so its pressures are the strain
    e): every force and taxel pressure it gives is the response per pascal of E, and
    the material scales it (the elastic response is linear in E).

    **Fields:**

    - `name`: the sensor's name (static).
    - `field`: the unit-modulus PressureField of the elastomer, frame S.
    - `clusters`: TetClusters of its tets, for the contact broad phase.
    - `layout`: the taxels.
    - `contact_center_S`: (3,) the centre from which contact angles are measured
      (NaN where the sensor defines none, as for a flat pad).
    - `num_rays`: rays per receptive field (static).
    """

    name: str = eqx.field(static=True)
    field: PressureField
    clusters: TetClusters
    layout: TaxelLayout
    contact_center_S: Float[Array, " 3"]
    num_rays: int = eqx.field(static=True)

    @property
    def num_taxels(self) -> int:
        return self.layout.num_taxels

    @property
    def has_contact_angles(self) -> bool:
        return bool(np.all(np.isfinite(np.asarray(self.contact_center_S))))


class Material(eqx.Module):
    """The elastomer's hydroelastic modulus E in Pa (elastic; the viscoelastic stage
    relaxes it in time with Prony terms)."""

    modulus: Float[Array, ""]


def make_material(modulus) -> Material:
    modulus = float(modulus)
    if not np.isfinite(modulus) or modulus <= 0.0:
        raise HydrotactError(f"the modulus must be a positive pressure in Pa, got {modulus!r}")
    return Material(jnp.asarray(modulus))


def make_sensor_model(spec, field_kind: str = "laplace", num_rays: int = 64, mesh=None) -> SensorModel:
    """Mesh the sensor of a :class:`hydrotact.sensors.SensorSpec` (or a built-in name or
    a spec file), solve its unit strain field and lay out its taxels (host).

    `field_kind` is "laplace" (the physical field) or "distance" (Drake's, for
    comparisons); `mesh` overrides the spec's geometry (e.g. a finer mesh).
    """
    from ..sensors import SensorSpec, load_sensor

    if not isinstance(spec, SensorSpec):
        spec = load_sensor(spec)
    if field_kind not in FIELD_KINDS:
        raise HydrotactError(f"unknown field kind {field_kind!r}; use one of {FIELD_KINDS}")
    if num_rays < 1:
        raise HydrotactError(f"num_rays must be at least 1, got {num_rays}")
    mesh = spec.make_mesh() if mesh is None else mesh
    if field_kind == "laplace":
        strain = solve_strain(make_laplace_problem(mesh, source=spec.name)).strain
    else:
        strain = jnp.asarray(calc_distance_field(mesh, source=spec.name))
    center = spec.contact_center_S
    return SensorModel(
        name=spec.name,
        field=make_pressure_field(mesh, strain, 1.0),
        clusters=make_tet_clusters(mesh.vertices, mesh.tets),
        layout=make_taxel_layout(spec.taxel_positions_S, spec.taxel_axes_S, spec.taxel_field_kinds, spec.taxel_field_sizes),
        contact_center_S=jnp.asarray(np.full(3, np.nan) if center is None else np.asarray(center, dtype=np.float64)),
        num_rays=int(num_rays),
    )
