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
from .._types import Array, Float, Int
from ..contact import TetClusters, make_tet_clusters
from ..elastic import ReceptiveFields, make_receptive_fields
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
    - `elastic`: the receptive fields of the barometers that read the elastomer's
      stress (:class:`hydrotact.elastic.ReceptiveFields`), or None when none does.
    - `elastic_channels`: (num_elastic,) their channel indices, or None.
    - `uses_rays`: whether any barometer is a ray-cast taxel (static; without one the
      ray caster is not run).
    """

    field: PressureField
    clusters: TetClusters
    layout: TaxelLayout
    contact_center_S: Float[Array, " 3"]
    num_rays: int = eqx.field(static=True)
    elastic: ReceptiveFields | None = None
    elastic_channels: Int[Array, " num_elastic"] | None = None
    uses_rays: bool = eqx.field(static=True, default=True)

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
    model = SensorModel(
        field=make_pressure_field(mesh, strain, 1.0),
        clusters=make_tet_clusters(mesh.vertices, mesh.tets),
        layout=make_ray_layout(spec, spec.taxel_positions_S),
        contact_center_S=jnp.asarray(np.full(3, np.nan) if center is None else np.asarray(center, dtype=np.float64)),
        num_rays=int(num_rays),
        uses_rays=bool(not spec.is_elastic.all()),
    )
    return with_barometer_positions(model, spec, spec.taxel_positions_S, mesh=mesh)


def make_ray_layout(spec, positions_S) -> TaxelLayout:
    """The ray-cast taxels' layout of a spec's barometers at `positions_S` (host). An
    elastic barometer keeps its place in it as a disk of its port's radius, whose
    reading the elastic one replaces."""
    kinds = tuple("disk" if kind == "elastic" else kind for kind in spec.taxel_field_kinds)
    return make_taxel_layout(positions_S, spec.taxel_axes_S, kinds, spec.taxel_field_sizes)


def with_barometer_positions(model: SensorModel, spec, positions_S, mesh=None, progress: bool = False) -> SensorModel:
    """`model` with the spec's barometers at `positions_S` (n, 3) m (host): the ray
    layout moved, and the elastic barometers' receptive fields solved for the new
    ports (cached by content; :func:`hydrotact.elastic.make_receptive_fields`)."""
    positions_S = np.asarray(positions_S, dtype=np.float64)
    model = eqx.tree_at(lambda m: m.layout, model, make_ray_layout(spec, positions_S))
    elastic = spec.is_elastic
    if not elastic.any():
        return model
    if mesh is None:
        mesh = spec.make_mesh()
    channels = np.flatnonzero(elastic)
    fields = make_receptive_fields(
        mesh,
        positions_S[channels],
        spec.taxel_axes_S[channels],
        spec.taxel_field_sizes[channels],
        [spec.taxel_elastic_readings[k] for k in channels],
        spec.poisson_ratio,
        progress=progress,
        source=spec.name,
    )
    return eqx.tree_at(
        lambda m: (m.elastic, m.elastic_channels), model, (fields, jnp.asarray(channels)), is_leaf=lambda leaf: leaf is None
    )
