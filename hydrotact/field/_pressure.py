"""The hydroelastic pressure field p = E e, linear in each tet."""

import equinox as eqx
import jax.numpy as jnp

from .._types import Array, Float, Int
from ._assembly import calc_tet_gradients


class PressureField(eqx.Module):
    """A piecewise-linear pressure field on a tet mesh (a pytree).

    p(x) = E e(x), with e the strain at the vertices interpolated linearly in each tet.
    Everything is differentiable in `vertices`, `strain` and `modulus`.

    **Fields:**

    - `vertices`: (num_vertices, 3) in metres, frame S.
    - `tets`: (num_tets, 4).
    - `strain`: (num_vertices,) e, dimensionless.
    - `modulus`: E in pascals (the hydroelastic modulus).
    """

    vertices: Float[Array, "num_vertices 3"]
    tets: Int[Array, "num_tets 4"]
    strain: Float[Array, " num_vertices"]
    modulus: Float[Array, ""]

    @property
    def vertex_pressures(self) -> Float[Array, " num_vertices"]:
        """Pressure at each vertex, in Pa."""
        return self.modulus * self.strain

    def calc_tet_pressure_gradients(self) -> Float[Array, "num_tets 3"]:
        """grad p in each tet (Pa/m), expressed in frame S."""
        gradients, _ = calc_tet_gradients(self.vertices, self.tets)
        return self.modulus * jnp.einsum("tid,ti->td", gradients, self.strain[self.tets])

    def calc_pressure(self, p_SQ, tet_index) -> Float[Array, "..."]:
        """Pressure (Pa) at points Q (..., 3) that lie in the given tets (...,)."""
        gradients, _ = calc_tet_gradients(self.vertices, self.tets)
        tet = self.tets[tet_index]
        p0 = self.vertices[tet[..., 0]]
        grad_e = jnp.einsum("...id,...i->...d", gradients[tet_index], self.strain[tet])
        return self.modulus * (self.strain[tet[..., 0]] + jnp.sum(grad_e * (p_SQ - p0), axis=-1))


def make_pressure_field(mesh, strain, modulus) -> PressureField:
    """The pressure field E e on `mesh` (strain from `solve_strain` or the distance field)."""
    strain = jnp.asarray(strain)
    return PressureField(
        vertices=jnp.asarray(mesh.vertices, strain.dtype),
        tets=jnp.asarray(mesh.tets),
        strain=strain,
        modulus=jnp.asarray(modulus, strain.dtype),
    )
