"""Gradient-safe maths: finite values and finite gradients at the singular points."""

import jax.numpy as jnp


def safe_norm(x, axis=-1, keepdims=False):
    """Euclidean norm along `axis` whose gradient at x = 0 is 0 instead of NaN."""
    squared = jnp.sum(x * x, axis=axis, keepdims=keepdims)
    is_zero = squared == 0.0
    safe_squared = jnp.where(is_zero, 1.0, squared)
    return jnp.where(is_zero, 0.0, jnp.sqrt(safe_squared))


def safe_div(numerator, denominator):
    """numerator / denominator, 0 where the denominator is 0 (and a zero gradient there)."""
    is_zero = denominator == 0.0
    safe_denominator = jnp.where(is_zero, 1.0, denominator)
    return jnp.where(is_zero, 0.0, numerator / safe_denominator)
