"""Benchmark: the strain-field solve (and solve + gradient) against scipy.sparse.

For box meshes from ~10k tets upwards, on the same assembled system in the same run:

- hydrotact: Jacobi-preconditioned CG (lineax) under jit, float64; timed after
  compilation (median of repeats); memory from XLA's compiled memory analysis
  (arguments + outputs + temporaries), and the device's peak on a GPU.
- solve + gradient: jax.grad of the mean strain with respect to all vertex positions.
- scipy direct: SuperLU (`spsolve`) on the reduced Dirichlet system; memory is the
  size of its L and U factors.
- scipy CG: `scipy.sparse.linalg.cg` with the same Jacobi preconditioner and tolerance.

Run: `.venv/bin/python benchmarks/field.py [--max-tets N] [--repeats R]`; it prints a
Markdown table and writes benchmarks/results/field-<backend>.json.
"""

import argparse
import json
import statistics
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402
from _machine import describe_machine  # noqa: E402

from hydrotact.field import calc_stiffness_values, make_laplace_problem, solve_strain  # noqa: E402
from hydrotact.mesh import make_box  # noqa: E402

RTOL = 1e-10


def _median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _compiled_bytes(jitted, *args):
    analysis = jitted.lower(*args).compile().memory_analysis()
    if analysis is None:
        return None
    return int(analysis.argument_size_in_bytes + analysis.output_size_in_bytes + analysis.temp_size_in_bytes)


def run_size(edge_cells: int, repeats: int, max_direct_unknowns: int) -> dict:
    mesh = make_box((13.2e-3, 13.2e-3, 4e-3), 13.2e-3 / edge_cells)
    start = time.perf_counter()
    problem = make_laplace_problem(mesh)
    host_build = time.perf_counter() - start
    V = jnp.asarray(problem.vertices)

    solve = jax.jit(lambda prob, vertices: solve_strain(prob, vertices=vertices, rtol=RTOL))
    start = time.perf_counter()
    solution = jax.block_until_ready(solve(problem, V))
    first_call = time.perf_counter() - start
    solve_seconds = _median_time(lambda: solve(problem, V).strain, repeats)

    def mean_strain(prob, vertices):
        return jnp.mean(solve_strain(prob, vertices=vertices, rtol=RTOL).strain)

    gradient = jax.jit(jax.value_and_grad(mean_strain, argnums=1))
    jax.block_until_ready(gradient(problem, V))
    gradient_seconds = _median_time(lambda: gradient(problem, V), repeats)
    solve_bytes = _compiled_bytes(solve, problem, V)
    gradient_bytes = _compiled_bytes(gradient, problem, V)

    # The same reduced Dirichlet system for scipy.
    values = np.asarray(calc_stiffness_values(problem.pattern, V, problem.tets))
    rows, cols, entries = problem.pattern.to_coo(values)
    K = sp.csr_matrix((entries, (rows, cols)), shape=(mesh.num_vertices,) * 2)
    fixed = np.asarray(problem.is_free_vertex) | np.asarray(problem.is_core_vertex)
    u_fixed = np.where(np.asarray(problem.is_core_vertex), 1.0, 0.0)
    unknown = np.flatnonzero(~fixed)
    A = K[unknown][:, unknown].tocsc()
    b = -(K[unknown] @ u_fixed)
    if len(unknown) <= max_direct_unknowns:
        start = time.perf_counter()
        lu = spla.splu(A)
        x_direct = lu.solve(b)
        direct_seconds = time.perf_counter() - start
        direct_bytes = int((lu.L.nnz + lu.U.nnz) * 12)
    else:  # SuperLU's 3-D fill-in: minutes and >10 GB past this size on a 24 GB machine
        x_direct, direct_seconds, direct_bytes = None, None, None
    M = sp.diags(1.0 / A.diagonal())
    start = time.perf_counter()
    x_cg, info = spla.cg(A, b, rtol=RTOL, M=M, maxiter=10 * len(b))
    cg_seconds = time.perf_counter() - start
    ours = np.asarray(solution.strain)[unknown]
    reference = x_direct if x_direct is not None else x_cg
    return {
        "num_tets": mesh.num_tets,
        "num_vertices": mesh.num_vertices,
        "num_unknowns": int(len(unknown)),
        "host_build_s": host_build,
        "first_call_s": first_call,
        "solve_s": solve_seconds,
        "solve_and_gradient_s": gradient_seconds,
        "cg_iterations": int(solution.num_steps),
        "solve_bytes": solve_bytes,
        "solve_and_gradient_bytes": gradient_bytes,
        "device_peak_bytes": (jax.devices()[0].memory_stats() or {}).get("peak_bytes_in_use"),
        "scipy_direct_s": direct_seconds,
        "scipy_direct_factor_bytes": direct_bytes,
        "scipy_cg_s": cg_seconds,
        "scipy_cg_converged": info == 0,
        "max_abs_difference_vs_reference": float(np.max(np.abs(ours - reference))),
        "ratio_solve_vs_scipy_direct": None if direct_seconds is None else direct_seconds / solve_seconds,
        "ratio_solve_vs_scipy_cg": cg_seconds / solve_seconds,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-tets", type=float, default=2e6)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--max-direct-unknowns", type=int, default=150_000)
    args = parser.parse_args()
    machine = describe_machine()
    print(f"machine: {machine}")
    rows = []
    out = Path(__file__).parent / "results" / f"field-{machine['jax_backend']}.json"
    out.parent.mkdir(exist_ok=True)
    for edge_cells in (16, 24, 40, 64, 100, 128, 160):
        estimated_tets = 6 * edge_cells * edge_cells * max(1, round(edge_cells * 4 / 13.2))
        if estimated_tets > args.max_tets:
            break
        rows.append(run_size(edge_cells, args.repeats, args.max_direct_unknowns))
        print(_table_row(rows[-1]), flush=True)
        out.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
    print()
    print(HEADER)
    for row in rows:
        print(_table_row(row))
    print(f"\nwritten: {out}")


HEADER = (
    "| tets | unknowns | CG its | solve | solve+grad | XLA memory (solve / +grad) | scipy direct | direct factor "
    "| scipy CG | direct/ours | CG/ours | max diff |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
)


def _table_row(r: dict) -> str:
    def mib(b):
        return "n/a" if b is None else f"{b / 2**20:.0f} MiB"

    def ms(s):
        return "skipped" if s is None else f"{s * 1e3:.1f} ms"

    def ratio(x):
        return "n/a" if x is None else f"{x:.2f}"

    return (
        f"| {r['num_tets']:,} | {r['num_unknowns']:,} | {r['cg_iterations']} | {ms(r['solve_s'])} | "
        f"{ms(r['solve_and_gradient_s'])} | {mib(r['solve_bytes'])} / {mib(r['solve_and_gradient_bytes'])} | "
        f"{ms(r['scipy_direct_s'])} | {mib(r['scipy_direct_factor_bytes'])} | {ms(r['scipy_cg_s'])} | "
        f"{ratio(r['ratio_solve_vs_scipy_direct'])} | {ratio(r['ratio_solve_vs_scipy_cg'])} | "
        f"{r['max_abs_difference_vs_reference']:.1e} |"
    )


if __name__ == "__main__":
    main()
