"""Rigid poses X_AB: a rotation R_AB and a translation p_AB, as a pytree."""

import equinox as eqx
import jax.numpy as jnp

from .._math import safe_norm
from .._types import Array, Float


class Pose(eqx.Module):
    """The pose X_AB of frame B in frame A: p_AQ = R_AB p_BQ + p_AB.

    **Fields:**

    - `rotation`: (3, 3) R_AB, orthonormal with determinant +1.
    - `translation`: (3,) p_AB in metres.
    """

    rotation: Float[Array, "3 3"]
    translation: Float[Array, " 3"]

    def apply(self, p_BQ):
        """p_AQ for points p_BQ (..., 3)."""
        rotated = jnp.einsum("ij,...j->...i", self.rotation, p_BQ)
        return rotated + jnp.reshape(self.translation, (1,) * (rotated.ndim - 1) + (3,))

    def rotate(self, v_B):
        """v_A for vectors v_B (..., 3)."""
        return jnp.einsum("ij,...j->...i", self.rotation, v_B)

    def inverse(self) -> "Pose":
        """X_BA."""
        rotation_T = jnp.swapaxes(self.rotation, -1, -2)
        return Pose(rotation_T, -jnp.einsum("ij,j->i", rotation_T, self.translation))

    def compose(self, X_BC: "Pose") -> "Pose":
        """X_AC = X_AB X_BC."""
        return Pose(self.rotation @ X_BC.rotation, self.apply(X_BC.translation))

    def as_matrix(self):
        """The 4 x 4 homogeneous matrix."""
        top = jnp.concatenate([self.rotation, self.translation[:, None]], axis=1)
        return jnp.concatenate([top, jnp.array([[0.0, 0.0, 0.0, 1.0]], dtype=top.dtype)], axis=0)


def calc_rotation_from_vector(rotation_vector):
    """R = exp([w]x) for the rotation vector w (axis times angle, radians), by
    Rodrigues' formula with series near w = 0 so values and gradients stay finite."""
    w = jnp.asarray(rotation_vector)
    angle = safe_norm(w)
    small = angle < 1e-4
    safe_angle = jnp.where(small, 1.0, angle)
    # sin(t)/t and (1 - cos t)/t^2, by Taylor series below 1e-4 rad.
    a = jnp.where(small, 1.0 - angle**2 / 6.0, jnp.sin(safe_angle) / safe_angle)
    b = jnp.where(small, 0.5 - angle**2 / 24.0, (1.0 - jnp.cos(safe_angle)) / safe_angle**2)
    zero = jnp.zeros_like(w[0])
    hat = jnp.array([[zero, -w[2], w[1]], [w[2], zero, -w[0]], [-w[1], w[0], zero]])
    return jnp.eye(3, dtype=w.dtype) + a * hat + b * (hat @ hat)


def make_pose(translation=(0.0, 0.0, 0.0), rotation_vector=(0.0, 0.0, 0.0)) -> Pose:
    """X_AB from a translation p_AB (m) and a rotation vector (rad); differentiable."""
    translation = jnp.asarray(translation, dtype=jnp.result_type(float))
    rotation = calc_rotation_from_vector(jnp.asarray(rotation_vector, dtype=translation.dtype))
    return Pose(rotation, translation)
