"""Drake's hydroelastic contact as a reference.

Bodies are handed to Drake as files hydrotact wrote (a compliant tet mesh as legacy
VTK, a rigid surface as OBJ) or as Drake's own HalfSpace, so both codes work on
identical meshes and fields. Drake's answer is read back as polygons with their
pressures, and integrated here (independently of hydrotact's code) into area, force
and centroid.
"""

import numpy as np
from helpers import lowest_vertex


def _rigid_transform(X):
    from pydrake.math import RigidTransform

    return RigidTransform(np.asarray(X, dtype=float))


class DrakeScene:
    """A compliant mesh (`soft_vtk`, on a free body) and `other` fixed at X_WO: a Drake
    shape or a path (.obj rigid, .vtk compliant with `other_modulus`). Build once,
    then query at as many soft-body poses X_WS as needed."""

    def __init__(self, soft_vtk, modulus, other, X_WO=None, other_modulus=None):
        from pydrake.geometry import (
            AddCompliantHydroelasticProperties,
            AddRigidHydroelasticProperties,
            Mesh,
            ProximityProperties,
        )
        from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
        from pydrake.multibody.tree import SpatialInertia
        from pydrake.systems.framework import DiagramBuilder

        builder = DiagramBuilder()
        self.plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        self.body = self.plant.AddRigidBody("elastomer", SpatialInertia.SolidBoxWithMass(0.01, 0.01, 0.01, 0.01))
        soft = ProximityProperties()
        AddCompliantHydroelasticProperties(1.0, float(modulus), soft)
        self.plant.RegisterCollisionGeometry(self.body, _rigid_transform(np.eye(4)), Mesh(str(soft_vtk)), "elastomer", soft)
        properties = ProximityProperties()
        if isinstance(other, str) and other.endswith(".vtk"):
            AddCompliantHydroelasticProperties(1.0, float(other_modulus), properties)
            other = Mesh(other)
        elif isinstance(other, str):
            AddRigidHydroelasticProperties(1.0, properties)
            other = Mesh(other)
        else:
            AddRigidHydroelasticProperties(1.0, properties)
        X_WO = np.eye(4) if X_WO is None else X_WO
        self.plant.RegisterCollisionGeometry(self.plant.world_body(), _rigid_transform(X_WO), other, "other", properties)
        self.plant.Finalize()
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyContextFromRoot(self.context)
        self.scene_context = self.scene_graph.GetMyContextFromRoot(self.context)

    def query(self, X_WS=None):
        """[(ContactSurface, whether the soft body is Drake's M)] at soft-body pose X_WS."""
        from pydrake.geometry import HydroelasticContactRepresentation

        self.plant.SetFreeBodyPose(self.plant_context, self.body, _rigid_transform(np.eye(4) if X_WS is None else X_WS))
        query = self.scene_graph.get_query_output_port().Eval(self.scene_context)
        surfaces = query.ComputeContactSurfaces(HydroelasticContactRepresentation.kPolygon)
        inspector = query.inspector()
        return [(surface, inspector.GetName(surface.id_M()) == "elastomer") for surface in surfaces]


def drake_contact_surfaces(soft_vtk, modulus, other, X_WS=None, X_WO=None, other_modulus=None):
    """One query of a :class:`DrakeScene`: the soft mesh at X_WS, `other` at X_WO."""
    return DrakeScene(soft_vtk, modulus, other, X_WO, other_modulus).query(X_WS)


def integrate_drake_surface(surface, soft_is_M):
    """(area, force on the soft body, area centroid, polygon vertices, vertex pressures)
    of a Drake ContactSurface, by fan triangulation of its polygons (numpy).

    Drake's face normals point out of N into M, so the force on M is +int p n dA.
    """
    mesh = surface.poly_mesh_W()
    field = surface.poly_e_MN()
    points = np.array([mesh.vertex(i) for i in range(mesh.num_vertices())])
    pressure = np.array([field.EvaluateAtVertex(i) for i in range(mesh.num_vertices())])
    area = 0.0
    force = np.zeros(3)
    moment = np.zeros(3)
    for f in range(mesh.num_faces()):
        polygon = mesh.element(f)
        ids = [polygon.vertex(k) for k in range(polygon.num_vertices())]
        normal = np.asarray(mesh.face_normal(f))
        for k in range(1, len(ids) - 1):
            a, b, c = ids[0], ids[k], ids[k + 1]
            tri_area = 0.5 * np.dot(np.cross(points[b] - points[a], points[c] - points[a]), normal)
            area += tri_area
            force += tri_area * (pressure[a] + pressure[b] + pressure[c]) / 3.0 * normal
            moment += tri_area * (points[a] + points[b] + points[c]) / 3.0
    sign = 1.0 if soft_is_M else -1.0
    return area, sign * force, moment / area, points, pressure


def pressing_plane_pose(height):
    """Pose of a Drake HalfSpace (solid below z = 0 in its frame) flipped so that it
    fills z >= height: a flat plate pressed down onto the top of a sensor."""
    X = np.eye(4)
    X[:3, :3] = np.diag([1.0, -1.0, -1.0])
    X[2, 3] = height
    return X


# Poses the first agreement tests never tried (issue 12): tilted and edge-first probes,
# spheres off-axis on the curved sensors, half-spaces past the pad's mid-plane, all at
# depths that are not round numbers. Shared by tests/test_contact_drake.py and
# benchmarks/drake_agreement.py.
TILT = (0.26113296, 0.17353392, -0.02284617)  # 15 degrees about x, then 10 about y
OFF_AXIS_CASES = {
    "pad5x5, 2 mm cylinder tilted 15/10 degrees, 0.43 mm": ("pad5x5", "cylinder:d=2mm,length=6mm", TILT, (0.37e-3, -0.21e-3), 0.43e-3),
    "pad5x5, box pressed edge first, 0.31 mm": ("pad5x5", "box:x=4mm,y=4mm,z=2mm", (np.pi / 4, 0.0, 0.1), (-0.52e-3, 1.13e-3), 0.31e-3),
    "sphere8, 3 mm sphere off-axis, 0.37 mm": ("sphere8", "sphere:r=3mm", (0.0, 0.0, 0.0), (2.3e-3, -1.7e-3), 0.37e-3),
    "ellipsoid8, 3 mm sphere off-axis, 0.52 mm": ("ellipsoid8", "sphere:r=3mm", (0.0, 0.0, 0.0), (-3.1e-3, 1.2e-3), 0.52e-3),
    "pad5x5, half-space past the mid-plane, 2.47 mm": ("pad5x5", "plane", (0.0, 0.0, 0.0), (0.0, 0.0), 2.47e-3),
    "pad5x5, half-space past the mid-plane, 3.13 mm": ("pad5x5", "plane", (0.0, 0.0, 0.0), (0.0, 0.0), 3.13e-3),
}


def off_axis_case(label, scratch, modulus):
    """One of OFF_AXIS_CASES set up for both codes: (field, probe, X_SR, Drake's
    surfaces). The probe's lowest point goes `depth` below the skin above (x, y)."""
    from pydrake.geometry import HalfSpace as DrakeHalfSpace

    from hydrotact.contact import HalfSpace, calc_skin_height, make_pose, parse_probe
    from hydrotact.field import calc_distance_field, make_pressure_field
    from hydrotact.mesh import make_seed_mesh, read_mesh, write_mesh

    sensor, spec, rotation_vector, (x, y), depth = OFF_AXIS_CASES[label]
    path = write_mesh(make_seed_mesh(sensor), scratch / f"{sensor}.vtk")
    mesh, _ = read_mesh(path)
    field = make_pressure_field(mesh, calc_distance_field(mesh), modulus)
    probe = parse_probe(spec)
    X = np.eye(4)
    X[:3, :3] = np.asarray(make_pose(np.zeros(3), rotation_vector).rotation)
    X[:3, 3] = [x, y, calc_skin_height(mesh, x, y) - depth - lowest_vertex(probe, rotation_vector)[2]]
    if isinstance(probe, HalfSpace):
        drake = drake_contact_surfaces(path, modulus, DrakeHalfSpace(), X_WO=pressing_plane_pose(X[2, 3]))
    else:
        probe_path = scratch / f"off-axis-probe-{list(OFF_AXIS_CASES).index(label)}.obj"  # its own file: callers keep theirs
        probe.write_obj(probe_path)
        drake = drake_contact_surfaces(path, modulus, str(probe_path), X_WO=X)
    return field, probe, make_pose(X[:3, 3], rotation_vector), drake
