"""Gradient-safe maths: finite values and finite gradients at the singular points."""

import jax.numpy as jnp


def safe_norm(x, axis=-1, keepdims=False):
    """Euclidean norm along `axis` whose gradient at x = 0 is 0 instead of NaN."""
    return safe_sqrt(jnp.sum(x * x, axis=axis, keepdims=keepdims))


def safe_sqrt(squared):
    """sqrt of a non-negative value whose gradient at 0 is 0 instead of inf."""
    is_zero = squared == 0.0
    return jnp.where(is_zero, 0.0, jnp.sqrt(jnp.where(is_zero, 1.0, squared)))


def safe_div(numerator, denominator):
    """numerator / denominator, 0 where the denominator is 0 (and a zero gradient there)."""
    is_zero = denominator == 0.0
    safe_denominator = jnp.where(is_zero, 1.0, denominator)
    return jnp.where(is_zero, 0.0, numerator / safe_denominator)

