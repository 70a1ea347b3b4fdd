"""Small dense linear algebra over a batch, one matrix at a time (jittable).

jaxlib 0.10's CPU LAPACK kernels (getrf, trsm, potrf and the rest) split a *batch*
of matrices over XLA's intra-op thread pool and block the calling pool thread until
the pieces are done. When a program runs as many batched calls at once as the pool
has threads (XLA runs independent operations concurrently), every thread waits for
pieces that no thread is free to run, and the process stops for good, using no CPU:
two concurrent batched `jnp.linalg.solve`s hang a 2-core machine every time
(tests/test_lumped.py), and a lumped fit of three real stage logs hung so. (jax
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


def _each(function, batch, *arrays):
    """function over the matrices of arrays, whose leading axes `batch` they share,
    one at a time (`lax.map`); called directly where there is no batch."""
    if not batch:
        return function(*arrays)
    out = jax.lax.map(lambda items: function(*items), tuple(x.reshape(-1, *x.shape[len(batch) :]) for x in arrays))
    return jax.tree_util.tree_map(lambda o: o.reshape(*batch, *o.shape[1:]), out)


def lu_factor(a):
    """`jax.scipy.linalg.lu_factor` of each matrix of a (..., n, n): (lu, pivots)."""
    return _each(jsp_linalg.lu_factor, a.shape[:-2], a)


def lu_solve(factors, b):
    """`jax.scipy.linalg.lu_solve` per matrix: factors from :func:`lu_factor` of a
    (..., n, n), b (..., n) or (..., n, k) with the same batch axes."""
    lu, pivots = factors
    return _each(lambda lu, pivots, b: jsp_linalg.lu_solve((lu, pivots), b), lu.shape[:-2], lu, pivots, b)


def solve(a, b):
    """`jnp.linalg.solve` per matrix: a (..., n, n), b (..., n) (one vector each)."""
    return _each(jnp.linalg.solve, a.shape[:-2], a, b)


def inv(a):
    """`jnp.linalg.inv` per matrix of a (..., n, n)."""
    return _each(jnp.linalg.inv, a.shape[:-2], a)


def slogdet(a):
    """`jnp.linalg.slogdet` per matrix of a (..., n, n): (sign, log |det|)."""
    return _each(lambda m: tuple(jnp.linalg.slogdet(m)), a.shape[:-2], a)


def inv3(a):
    """The inverse of each 3 x 3 matrix of a (..., 3, 3) in closed form (the adjugate
    over the determinant; no LAPACK): for many small, well-conditioned blocks."""
    c0 = jnp.cross(a[..., 1, :], a[..., 2, :])
    c1 = jnp.cross(a[..., 2, :], a[..., 0, :])
    c2 = jnp.cross(a[..., 0, :], a[..., 1, :])
    det = jnp.sum(a[..., 0, :] * c0, axis=-1)
    return jnp.stack([c0, c1, c2], axis=-1) / det[..., None, None]
