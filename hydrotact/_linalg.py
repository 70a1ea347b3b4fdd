"""Small dense linear algebra over a batch, one matrix at a time (jittable).

jaxlib 0.10's CPU LAPACK kernels (getrf, trsm, potrf and the rest) split a *batch*
of matrices over XLA's intra-op thread pool and block the calling pool thread until
the pieces are done. When a program runs as many batched calls at once as the pool
has threads (XLA runs independent operations concurrently), every thread waits for
pieces that no thread is free to run, and the process stops for good, using no CPU:
two concurrent batched `jnp.linalg.solve`s hang a 2-core machine every time
(tests/test_sysid.py), and a lumped fit of three real stage logs hung so. (jax
0.11.2 compiles that path out; 0.10.2 is the newest on PyPI as this is written.) One
matrix at a time runs inline on the calling thread, so these helpers map over the
batch with `lax.map`: the same LAPACK routine per matrix, the same numbers.

Under `vmap` a `lax.map` batches again: call these where the batch is the data's
own (channels, contacts), not inside a function that is itself vmapped over
matrices (a vmap over right-hand sides with the matrices held is fine: the solve
folds them into its columns).
"""

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsp_linalg


def lu_factor(a):
    """`jax.scipy.linalg.lu_factor` of each matrix of a (..., n, n): (lu, pivots)."""
    batch = a.shape[:-2]
    if not batch:
        return jsp_linalg.lu_factor(a)
    lu, pivots = jax.lax.map(jsp_linalg.lu_factor, a.reshape(-1, *a.shape[-2:]))
    return lu.reshape(a.shape), pivots.reshape(*batch, pivots.shape[-1])


def lu_solve(factors, b):
    """`jax.scipy.linalg.lu_solve` per matrix: factors from :func:`lu_factor` of a
    (..., n, n), b (..., n) or (..., n, k) with the same batch axes."""
    lu, pivots = factors
    batch = lu.shape[:-2]
    if not batch:
        return jsp_linalg.lu_solve((lu, pivots), b)
    flat = (lu.reshape(-1, *lu.shape[-2:]), pivots.reshape(-1, pivots.shape[-1]), b.reshape(-1, *b.shape[len(batch) :]))
    out = jax.lax.map(lambda items: jsp_linalg.lu_solve((items[0], items[1]), items[2]), flat)
    return out.reshape(*batch, *out.shape[1:])


def solve(a, b):
    """`jnp.linalg.solve` per matrix: a (..., n, n), b (..., n) (one vector each)."""
    batch = a.shape[:-2]
    if not batch:
        return jnp.linalg.solve(a, b)
    out = jax.lax.map(lambda items: jnp.linalg.solve(items[0], items[1]), (a.reshape(-1, *a.shape[-2:]), b.reshape(-1, b.shape[-1])))
    return out.reshape(*batch, b.shape[-1])


def inv(a):
    """`jnp.linalg.inv` per matrix of a (..., n, n)."""
    batch = a.shape[:-2]
    if not batch:
        return jnp.linalg.inv(a)
    return jax.lax.map(jnp.linalg.inv, a.reshape(-1, *a.shape[-2:])).reshape(a.shape)


def slogdet(a):
    """`jnp.linalg.slogdet` per matrix of a (..., n, n): (sign, log |det|)."""
    batch = a.shape[:-2]
    if not batch:
        return jnp.linalg.slogdet(a)
    sign, log = jax.lax.map(lambda m: tuple(jnp.linalg.slogdet(m)), a.reshape(-1, *a.shape[-2:]))
    return sign.reshape(batch), log.reshape(batch)


def inv3(a):
    """The inverse of each 3 x 3 matrix of a (..., 3, 3) in closed form (the adjugate
    over the determinant; no LAPACK): for many small, well-conditioned blocks."""
    c0 = jnp.cross(a[..., 1, :], a[..., 2, :])
    c1 = jnp.cross(a[..., 2, :], a[..., 0, :])
    c2 = jnp.cross(a[..., 0, :], a[..., 1, :])
    det = jnp.sum(a[..., 0, :] * c0, axis=-1)
    return jnp.stack([c0, c1, c2], axis=-1) / det[..., None, None]
