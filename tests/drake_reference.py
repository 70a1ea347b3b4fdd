"""Drake's hydroelastic contact as a reference: load hydrotact's .vtk in Drake as a
compliant mesh and query contact surfaces against a rigid geometry."""

import numpy as np


def drake_contact_surfaces(vtk_path, modulus, rigid_shape, X_WR, X_WS=None):
    """Contact surfaces between the compliant mesh in `vtk_path` (frame S, placed at
    X_WS, default identity) and a rigid Drake shape at pose X_WR (4x4 matrices).

    Returns Drake's list of ContactSurface (polygon representation).
    """
    from pydrake.geometry import (
        AddCompliantHydroelasticProperties,
        AddRigidHydroelasticProperties,
        HydroelasticContactRepresentation,
        Mesh,
        ProximityProperties,
    )
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.multibody.tree import SpatialInertia
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    body = plant.AddRigidBody("elastomer", SpatialInertia.SolidBoxWithMass(0.01, 0.01, 0.01, 0.01))
    soft = ProximityProperties()
    AddCompliantHydroelasticProperties(1.0, float(modulus), soft)
    plant.RegisterCollisionGeometry(body, RigidTransform(), Mesh(str(vtk_path)), "elastomer", soft)
    rigid = ProximityProperties()
    AddRigidHydroelasticProperties(1.0, rigid)
    plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform(np.asarray(X_WR)), rigid_shape, "probe", rigid)
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    plant.SetFreeBodyPose(plant_context, body, RigidTransform(np.eye(4) if X_WS is None else np.asarray(X_WS)))
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    return query.ComputeContactSurfaces(HydroelasticContactRepresentation.kPolygon)


def pressing_plane_pose(height):
    """Pose of a Drake HalfSpace (solid below z = 0 in its frame) flipped so that it
    fills z >= height: a flat plate pressed down onto the top of a sensor."""
    X = np.eye(4)
    X[:3, :3] = np.diag([1.0, -1.0, -1.0])
    X[2, 3] = height
    return X
