"""Printing reports: a two-column rich table, or JSON with --json."""

import contextlib
import json


@contextlib.contextmanager
def status(message: str):
    """A spinner with `message` on stderr while a slow step runs (on a terminal; shows
    nothing when stderr is a file or a pipe)."""
    from rich.console import Console

    console = Console(stderr=True)
    if not console.is_terminal:
        yield
        return
    with console.status(message):
        yield


def print_report(title: str, report: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(report, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, show_header=False)
    for key, value in report.items():
        if isinstance(value, float):
            value = f"{value:.6g}"
        table.add_row(key, str(value))
    Console().print(table)
