"""Shared test helpers: finite differences, closed surfaces, running the CLI, counting
XLA compilations."""

import contextlib
import subprocess
import sys

import jax
import jax.extend
import numpy as np
import trimesh


def central_difference(f, x, direction, step):
    """(f(x + step d) - f(x - step d)) / (2 step) as a float."""
    return (float(f(x + step * direction)) - float(f(x - step * direction))) / (2.0 * step)


def icosphere(radius=5e-3, subdivisions=3, center=(0.0, 0.0, 0.0)):
    surface = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    surface.apply_translation(center)
    return surface


def box_surface(extents=(6e-3, 6e-3, 3e-3)):
    surface = trimesh.creation.box(extents=extents)
    surface.apply_translation([0.0, 0.0, extents[2] / 2])
    return surface


def lowest_vertex(probe, rotation_vector):
    """The probe's lowest vertex along z (3,), in its frame R turned by
    `rotation_vector`; R's origin for a half-space."""
    from hydrotact.contact import HalfSpace, make_pose

    if isinstance(probe, HalfSpace):
        return np.zeros(3)
    turned = np.asarray(probe.vertices_R) @ np.asarray(make_pose(np.zeros(3), rotation_vector).rotation).T
    return turned[np.argmin(turned[:, 2])]


def run_cli(*args, cwd=None):
    """Run `hydrotact ARGS` in a subprocess; returns CompletedProcess (text)."""
    return subprocess.run(
        [sys.executable, "-m", "hydrotact.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )


def run_main(capsys, *args):
    """`hydrotact ARGS` in this process (programs compiled here are reused); returns a
    CompletedProcess as run_cli does, argparse's exit turned into the status."""
    from hydrotact.cli import main

    try:
        code = main([str(arg) for arg in args])
    except SystemExit as exit_:
        code = exit_.code
    captured = capsys.readouterr()
    return subprocess.CompletedProcess(list(args), code, captured.out, captured.err)


def assert_one_line_error(result, *fragments):
    """The CLI failed with exit 2 and one `hydrotact: error:` line naming `fragments`."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("hydrotact: error: "), lines[0]
    assert "Traceback" not in result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def tet_barycentric(vertices, tets, points):
    """Barycentric coordinates (num_points, num_tets, 4) of points in every tet."""
    p = vertices[tets]
    edges = np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1))  # (T, 3, 3) columns e1, e2, e3
    inverse = np.linalg.inv(edges)
    local = np.einsum("tij,ptj->pti", inverse, points[:, None, :] - p[None, :, 0])
    return np.concatenate([1.0 - local.sum(-1, keepdims=True), local], axis=-1)


def locate(vertices, tets, points, tolerance=1e-9):
    """Index of a tet containing each point (the lowest, where several do) and the
    point's barycentric coordinates. Only the tets whose centroid lies within the
    largest centroid-to-vertex distance of a point can hold it (scipy's k-d tree)."""
    from scipy.spatial import cKDTree

    corners = vertices[tets]
    centroids = corners.mean(axis=1)
    radius = float(np.linalg.norm(corners - centroids[:, None], axis=-1).max())
    near = cKDTree(centroids).query_ball_point(points, radius * (1.0 + 1e-9) + tolerance)
    index = np.empty(len(points), dtype=np.int64)
    bary = np.empty((len(points), 4))
    for k, candidates in enumerate(near):
        candidates = np.sort(np.asarray(candidates, dtype=np.int64))
        inside = np.all((found := tet_barycentric(vertices, tets[candidates], points[k : k + 1])[0]) >= -tolerance, axis=-1)
        assert inside.any(), f"point {k} lies outside the mesh"
        first = int(np.argmax(inside))
        index[k], bary[k] = candidates[first], found[first]
    return index, bary


@contextlib.contextmanager
def count_compilations():
    """Collects one entry (its duration, s) per XLA backend compilation inside the
    block (a program found in the persistent cache is not compiled, not counted)."""
    compilations = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compilations.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield compilations
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


LAPACK_PRIMITIVES = {"lu", "triangular_solve", "cholesky", "eigh", "svd", "qr", "geqrf", "householder_product", "schur", "tridiagonal_solve", "eig", "hessenberg", "tridiagonal"}


def batched_lapack_calls(closed_jaxpr) -> list[str]:
    """The LAPACK primitives of a jaxpr (and every jaxpr inside it) whose matrix
    operand carries batch axes: on the CPU, jaxlib 0.10 splits such a call over XLA's
    thread pool and can deadlock (hydrotact._linalg). Each as 'name shape'."""
    found = []

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            if eqn.primitive.name in LAPACK_PRIMITIVES and eqn.invars[0].aval.ndim > 2:
                found.append(f"{eqn.primitive.name} {eqn.invars[0].aval.shape}")
            for value in eqn.params.values():
                for item in value if isinstance(value, (tuple, list)) else (value,):
                    if isinstance(item, jax.extend.core.ClosedJaxpr):
                        walk(item.jaxpr)
                    elif isinstance(item, jax.extend.core.Jaxpr):
                        walk(item)

    walk(closed_jaxpr.jaxpr)
    return found


def write_mould(path, outer, hollows=(), formers=()):
    """An STL mould part in mm: the box `outer` ((lo, hi) corners) less the boxes
    `hollows`, plus the boxes `formers` (features that stand into a cavity). Built with
    manifold3d, so the file is a closed solid; returns the path."""
    import manifold3d

    def box(lo, hi):
        return manifold3d.Manifold.cube(tuple(float(h - lo_) for lo_, h in zip(lo, hi))).translate(tuple(map(float, lo)))

    solid = box(*outer)
    for hollow in hollows:
        solid = solid - box(*hollow)
    for former in formers:
        solid = solid + box(*former)
    mesh = solid.to_mesh()
    trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3]), np.asarray(mesh.tri_verts), process=False).export(str(path))
    return path
