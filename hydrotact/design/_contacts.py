"""The contacts a layout is designed for: presses at skin points drawn uniformly by area,
at target forces drawn like a dataset's, each linearised in where it is and how hard.

A contact is the dataset regime's press straight along the inward skin normal n at a
skin point p, to the depth d where the force along the approach reaches its target.
Its contact surface is a function of q = (u, v, d): the probe's tip at p + u t1 + v t2
+ d n, with (t1, t2) a tangent frame at p. At u = v = 0 a change of u or v moves the
contact along the skin (to first order; the skin's curvature enters at second order),
so the surface's tangents along q carry everything the readings can say about where and
how deep the contact is. The contact surface does not depend on the layout: it is
computed and linearised once (`jax.linearize` of the contact stage), and each step of a
design only samples the taxels (:func:`hydrotact.taxel.calc_taxel_pressures`) of these
fixed surfaces and their tangents. The force along the approach is linearised too
(dF/dq), which turns the information about (u, v, d) into information about (u, v, F).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._buffers import run_growing
from .._types import Array, Bool, Float, Int
from ..contact import Capacity, ContactSurface, calc_contact_surface, make_pose

START_CAPACITY = Capacity(tets=1024, others=256, pairs=4096, polygons=1024)
"""The contact buffers a design starts with: what a 3 mm sphere pressed to 8 N into a
10 MPa sphere8 needs, rounded up (each growth compiles the contact kernels again)."""
DEPTH_ITERATIONS = 8
"""Safeguarded secant steps in log depth for the depth of a target force (a power law
F ~ d^k is solved in one; the bracket keeps every step inside (0, the deepest allowed])."""
FIRST_DEPTH = 5e-4
"""Where each depth search starts, m (half a millimetre: a few newtons on the built-ins)."""


class DesignContacts(eqx.Module):
    """Linearised contacts (a pytree with a leading contact axis N).

    **Fields:**

    - `surfaces`: the ContactSurface of each contact at unit modulus (E = 1 Pa).
    - `tangents`: its derivatives along q = (u, v, d) (a ContactSurface pytree with an
      extra axis of 3 after N; integer fields carry no tangent).
    - `force_jacobians`: (N, 3) dF/dq of the force along the approach, N/m.
    - `points_S`, `normals_S`: (N, 3) the skin points and their outward normals.
    - `forces`: (N,) the force along the approach at the contact, N.
    - `depths`: (N,) its depth, m.
    - `modulus`: the modulus the forces are computed with, Pa (the material's E(0)).
    """

    surfaces: ContactSurface
    tangents: ContactSurface
    force_jacobians: Float[Array, "num_contacts 3"]
    points_S: Float[Array, "num_contacts 3"]
    normals_S: Float[Array, "num_contacts 3"]
    forces: Float[Array, " num_contacts"]
    depths: Float[Array, " num_contacts"]
    modulus: Float[Array, ""]

    @property
    def num_contacts(self) -> int:
        return self.forces.shape[0]


class _Linearised(eqx.Module):
    surfaces: ContactSurface
    tangents: ContactSurface
    force_jacobians: Float[Array, "n 3"]
    forces: Float[Array, " n"]
    did_overflow: Bool[Array, " n"]
    needed: Int[Array, "n 4"]


def _tangent_frame(direction):
    helper = jnp.where(jnp.abs(direction[2]) < 0.9, jnp.array([0.0, 0.0, 1.0]), jnp.array([1.0, 0.0, 0.0]))
    t1 = jnp.cross(direction, helper)
    t1 = t1 / jnp.linalg.norm(t1)
    return t1, jnp.cross(direction, t1)


def _surface(model, probe, q, point, direction, rotation, capacity):
    t1, t2 = _tangent_frame(direction)
    X_SR = make_pose(point + q[0] * t1 + q[1] * t2 + q[2] * direction, rotation)
    return calc_contact_surface(model.field, probe, X_SR, capacity, model.clusters)


def _linearise(model, probe, capacity, depth, point, direction, rotation):
    surface, tangent = jax.linearize(lambda q: _surface(model, probe, q, point, direction, rotation, capacity), jnp.array([0.0, 0.0, depth]))
    tangents = jax.vmap(tangent)(jnp.eye(3))
    force_jacobian = jax.vmap(lambda t: jnp.dot(jax.jvp(lambda s: s.calc_force(), (surface,), (t,))[1], direction))(tangents)
    return _Linearised(surface, tangents, force_jacobian, jnp.dot(surface.calc_force(), direction), surface.did_overflow, surface.needed)


class _Forces(eqx.Module):
    forces: Float[Array, " n"]
    did_overflow: Bool[Array, " n"]
    needed: Int[Array, "n 4"]


def _force(model, probe, capacity, depth, point, direction, rotation):
    surface = _surface(model, probe, jnp.array([0.0, 0.0, depth]), point, direction, rotation, capacity)
    return _Forces(jnp.dot(surface.calc_force(), direction), surface.did_overflow, surface.needed)


@eqx.filter_jit
def _force_kernel(model, probe, capacity, depths, points, directions, rotations):
    return jax.lax.map(lambda args: _force(model, probe, capacity, *args), (depths, points, directions, rotations), batch_size=8)


@eqx.filter_jit
def _linear_kernel(model, probe, capacity, depths, points, directions, rotations):
    return jax.lax.map(lambda args: _linearise(model, probe, capacity, *args), (depths, points, directions, rotations), batch_size=8)


def linearise_contacts(model, probe, modulus: float, points_S, normals_S, target_forces, deepest, rotation_vectors, target_depths=None) -> DesignContacts:
    """Press `probe` into `model` at each skin point along its inward normal to the
    depth of its target force (N) at `modulus` (Pa), or to `target_depths` (m) when
    given (the paper's regime), no deeper than `deepest` (m), and linearise each
    contact (host: grows the contact buffers as needed).

    As in a dataset, a press whose target is out of reach by `deepest` stops there:
    its contact keeps the force it reached (`forces`)."""
    points = jnp.asarray(points_S, dtype=jnp.float64)
    directions = -jnp.asarray(normals_S, dtype=jnp.float64)
    targets = jnp.asarray(target_forces, dtype=jnp.float64)
    rotations = jnp.asarray(rotation_vectors, dtype=jnp.float64)
    modulus_ = jnp.asarray(float(modulus))
    deepest = np.broadcast_to(np.asarray(deepest, dtype=np.float64), targets.shape)
    capacity = fitted = START_CAPACITY
    if target_depths is not None:
        return _linearised(model, probe, modulus_, points, normals_S, directions, rotations, np.minimum(np.asarray(target_depths, dtype=np.float64), deepest), fitted)

    def grown(kernel, depths, start):
        result, fitted = run_growing(lambda c: kernel(model, probe, c, jnp.asarray(depths), points, directions, rotations), start)
        return result, fitted.rounded_up()

    def log_force_gap(x):
        nonlocal capacity, fitted
        result, fitted = grown(_force_kernel, np.exp(x), capacity)
        # Never shrunk during the search: its iterates go deeper and shallower, and each
        # new capacity compiles the kernel again.
        capacity = type(capacity)(*(int(size) for size in np.maximum(capacity.sizes, fitted.sizes)))
        force = modulus * np.asarray(result.forces)
        return np.log(np.maximum(force, 1e-300)) - np.log(np.asarray(targets))

    # The secant method on log F against log d (a power law F ~ d^k is solved in one
    # step), kept inside the bracket of depths known to fall short of the target and
    # depths known to exceed it (bisection where a step would leave it). Forward
    # contacts only: the linearisation is compiled once, at the depths found.
    low, high = np.full(len(deepest), np.log(1e-9)), np.log(deepest)
    x_old = np.log(np.minimum(FIRST_DEPTH, 0.5 * deepest))
    f_old = log_force_gap(x_old)
    x = np.minimum(x_old + np.where(f_old < 0.0, 0.5, -0.5), high)
    for _ in range(DEPTH_ITERATIONS):
        f = log_force_gap(x)
        for value, gap in ((x_old, f_old), (x, f)):
            low, high = np.where(gap < 0.0, np.maximum(low, value), low), np.where(gap >= 0.0, np.minimum(high, value), high)
        slope = (f - f_old) / np.where(x != x_old, x - x_old, 1.0)
        secant = x - f / np.where(slope > 0.0, slope, 1.0)
        x_old, f_old = x, f
        x = np.where((slope > 0.0) & (secant > low) & (secant < high), secant, 0.5 * (low + high))
        x = np.where(np.abs(f) < 1e-6, x_old, x)  # converged: stay
    # Sized to the last iterate's contacts, not the deepest met: the linearised contact
    # compiles in about a minute on a laptop CPU and its memory grows with the buffers.
    return _linearised(model, probe, modulus_, points, normals_S, directions, rotations, np.exp(x), fitted)


def _linearised(model, probe, modulus, points, normals_S, directions, rotations, depths, capacity) -> DesignContacts:
    linear, _ = run_growing(lambda c: _linear_kernel(model, probe, c, jnp.asarray(depths), points, directions, rotations), capacity)
    forces = modulus * np.asarray(linear.forces)
    return DesignContacts(
        surfaces=linear.surfaces,
        tangents=linear.tangents,
        force_jacobians=modulus * linear.force_jacobians,
        points_S=points,
        normals_S=jnp.asarray(normals_S, dtype=jnp.float64),
        forces=jnp.asarray(forces),
        depths=jnp.asarray(depths),
        modulus=modulus,
    )
