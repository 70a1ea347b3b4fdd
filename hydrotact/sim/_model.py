"""The device-side model of a sensor: its unit-modulus pressure field, tet clusters
for the contact search, and its taxel layout.

The material is not part of the model: it is a `visco.Prony` (an elastic material is
one with no terms), and the model's field has unit modulus, so every response it gives
is per pascal of E and the material acts on it (the elastic response is linear in E).
"""

import json
import os

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._types import Array, Float
from ..contact import TetClusters, make_tet_clusters
from ..field import PressureField, StrainFieldKind, calc_distance_field, make_laplace_problem, make_pressure_field, solve_strain
from ..taxel import TaxelLayout, make_taxel_layout


class SensorModel(eqx.Module):
    """A sensor ready to simulate (a pytree, built once on the host).

    The pressure field has unit modulus (E = 1 Pa, so its pressures are the strain
    e): every force and taxel pressure it gives is the response per pascal of E, and
    the material scales it (the elastic response is linear in E).

    It holds no name: the compiled programs that take it are the same for every
    sensor of one geometry and layout shape (a sensor file renamed, or one layout
    against another, compiles nothing again).

    **Fields:**

    - `field`: the unit-modulus PressureField of the elastomer, frame S.
    - `clusters`: TetClusters of its tets, for the contact broad phase.
    - `layout`: the taxels.
    - `contact_center_S`: (3,) the centre from which contact angles are measured
      (NaN where the sensor defines none, as for a flat pad).
    - `num_rays`: rays per receptive field (static).
    """

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


def make_sensor_model(spec, field_kind: StrainFieldKind | str = StrainFieldKind.LAPLACE, num_rays: int = 64, mesh=None) -> SensorModel:
    """Mesh the sensor of a :class:`hydrotact.sensors.SensorSpec` (or a built-in name or
    a spec file), solve its unit strain field and lay out its taxels (host).

    `field_kind` is a StrainFieldKind (or its name): "laplace" (the physical field)
    or "distance" (Drake's, for comparisons); `mesh` overrides the spec's geometry (e.g. a finer mesh).
    """
    from ..sensors import SensorSpec, load_sensor

    if not isinstance(spec, SensorSpec):
        spec = load_sensor(spec)
    field_kind = StrainFieldKind.parse(field_kind, "field kind")
    if num_rays < 1:
        raise HydrotactError(f"num_rays must be at least 1, got {num_rays}")
    if mesh is not None:
        return _make_sensor_model(spec, field_kind, int(num_rays), mesh)
    # Models are immutable: one per (spec, field, rays) serves every simulation and fit
    # of a session (building one meshes the elastomer and solves its field). A surface
    # file's modification time is part of the key: an edited file is meshed again.
    path = spec.geometry.path
    stamp = os.stat(path).st_mtime_ns if path is not None and os.path.exists(path) else None
    key = (json.dumps(spec.to_json(), sort_keys=True), stamp, str(field_kind), int(num_rays))
    if key not in _MODELS:
        _MODELS[key] = _make_sensor_model(spec, field_kind, int(num_rays), None)
    return _MODELS[key]


_MODELS: dict = {}


def _make_sensor_model(spec, field_kind, num_rays: int, mesh) -> SensorModel:
    mesh = spec.make_mesh() if mesh is None else mesh
    if field_kind == StrainFieldKind.LAPLACE:
        strain = solve_strain(make_laplace_problem(mesh, source=spec.name)).strain
    else:
        strain = jnp.asarray(calc_distance_field(mesh, source=spec.name))
    center = spec.contact_center_S
    return SensorModel(
        field=make_pressure_field(mesh, strain, 1.0),
        clusters=make_tet_clusters(mesh.vertices, mesh.tets),
        layout=make_taxel_layout(spec.taxel_positions_S, spec.taxel_axes_S, spec.taxel_field_kinds, spec.taxel_field_sizes),
        contact_center_S=jnp.asarray(np.full(3, np.nan) if center is None else np.asarray(center, dtype=np.float64)),
        num_rays=int(num_rays),
    )
