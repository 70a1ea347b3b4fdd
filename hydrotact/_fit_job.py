"""Moved; kept only so that `hydrotact._demo_job` still imports (it moves into
`hydrotact.sim`, and then this file goes).

`run_fit` -> `hydrotact.sysid.fit_logs` (which draws no pictures unless given
`plot=hydrotact.viz.plot_fit`), `read_logs` and `parse_terms` -> `hydrotact.sysid`,
`print_fit_table` -> `hydrotact.cli.fit`.
"""

from .cli.fit import print_fit_table as print_fit_table
from .sysid import fit_logs, parse_terms as parse_terms, read_logs as read_logs


def run_fit(paths, output, **options) -> dict:
    """`hydrotact.sysid.fit_logs` with the command line's plots (as before the move)."""
    from .viz import plot_fit

    options.setdefault("plot", plot_fit)
    return fit_logs(paths, output, **options)
