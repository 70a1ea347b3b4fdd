"""Array aliases shared across hydrotact, with their shapes in their names."""

from jaxtyping import Array, Bool, Float, Int

Scalar = Float[Array, ""]
Points = Float[Array, "num_points 3"]
Vertices = Float[Array, "num_vertices 3"]
VertexValues = Float[Array, " num_vertices"]
Tets = Int[Array, "num_tets 4"]
TetValues = Float[Array, " num_tets"]
TetVectors = Float[Array, "num_tets 3"]
Faces = Int[Array, "num_faces 3"]
FaceTags = Int[Array, " num_faces"]
VertexMask = Bool[Array, " num_vertices"]

__all__ = [
    "Array",
    "Bool",
    "Float",
    "Int",
    "Scalar",
    "Points",
    "Vertices",
    "VertexValues",
    "Tets",
    "TetValues",
    "TetVectors",
    "Faces",
    "FaceTags",
    "VertexMask",
]
