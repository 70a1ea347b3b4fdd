"""The user guide runs: every `$ hydrotact ...` line of docs/*.md and of the README's
tour, in order, page by page, in this process (so programs compiled for one command
serve the next), at smoke size; and the API overview names every public name.

A page is read top to bottom. A fenced block whose info string carries a title
(```json title="truth.json"```) is a file the page shows: it is written into the
page's working folder when reached, so the commands after it read it. A ```console
block's `$ hydrotact ...` lines (a trailing backslash continues a line) are run with
`hydrotact.cli.main`; each must exit 0 and leave the files it says it writes. Nothing
else is provided: the logs, mappings and sensors the commands read come from the pages.

SMOKE says how a command is shrunk: each option is set to the value given (added when
the page leaves it out), a callable maps the page's value (None when absent) to the
smoke value or to None (leave it). HYDROTACT_DOCS_TIMES=FILE appends each command's
CPU time to FILE. The sizes are the cheapest ones the other tests use
(tests/test_models_training.py TINY, experiments/ablation_table1.py SMOKE_REGIME,
tests/test_design.py)."""

import ast
import os
import re
import shlex
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
DOCS = ROOT / "docs"
PAGES = ["sensors.md", "fit.md", "generate.md", "train.md", "design.md"]  # in the order a user meets them
STAGES = ["mesh", "field", "contact", "taxel", "elastic", "sensors", "visco", "sim", "sysid", "data", "datasets", "models", "design", "viz"]

# The dataset regime's sphere, coarse (fewer contact polygons), as tests/test_design.py uses it.
COARSE_SPHERE = "sphere:r=3mm,subdivisions=1"


def _coarse(probe):
    return COARSE_SPHERE if probe in (None, "sphere:r=3mm") else None


SMOKE = {
    "simulate": {"--rays": "8", "--probe": lambda probe: _coarse(probe) if probe == "sphere:r=3mm" else None},
    "fit": {"--terms": "2", "--starts": "1"},
    "generate": {
        "--events": "12", "--rays": "8", "--hold-range": "0.3,0.8", "--gap-range": "0.2,0.4", "--speed-range": "0.01,0.02",
        "--force-range": "0.2,4", "--probe": _coarse,
    },
    "train": {"--max-epochs": "2", "--hidden": "6,6", "--sequence-length": "64", "--burn-in": "16", "--batch-size": "8"},
    # sphere8's elastic barometers would solve their fields' derivatives (minutes a
    # barometer): the smoke designs the same layout under ray-cast cones.
    "design": {
        "--contacts": "8", "--rays": "8", "--restarts": "1", "--steps": "6", "--probe": _coarse,
        "--sensor": lambda sensor: "sphere8-cones" if sensor == "sphere8" else None,
    },
    "demo": {"--smoke": True},
}
FLAGS = {"--smoke", "--json", "--no-plots", "--barometer", "--force", "--lumped", "--tare", "--plain", "--last-epoch", "--estimate-lag", "--randomise-material", "--field-sizes"}

FIT_FILES = ["material.json", "report.json", "traces.png", "residuals.png", "relaxation.png"]
DATASET_FILES = ["manifest.json", "shard-00000.parquet", "coverage.png", "histograms.png", "channel_swing.png", "examples.png"]


def _option(args, name):
    return args[args.index(name) + 1] if name in args else None


def _shrink(args):
    """The command's arguments with its SMOKE overrides applied."""
    args = list(args)
    for name, value in SMOKE.get(args[0], {}).items():
        if name == "--starts" and "--lumped" not in args:  # --starts is the lumped fit's
            continue
        if value is True:
            if name not in args:
                args.append(name)
            continue
        if callable(value):
            value = value(_option(args, name))
            if value is None:
                continue
        if name in args:
            args[args.index(name) + 1] = value
        else:
            args += [name, value]
    return args


def _outputs(args):
    """The files a command says it writes (its help and the docs say so)."""
    command, output = args[0], _option(args, "-o")
    files = [Path(p) for p in (output, _option(args, "--png"), _option(args, "--vtk")) if p is not None and command not in ("fit", "compare", "generate", "train", "evaluate", "demo")]
    folder = Path(output) if output is not None else None
    if command == "fit":
        files += [folder / name for name in FIT_FILES + (["channel_law_covariance.npz"] if "--lumped" in args else [])]
    elif command == "compare":
        files += [folder / name for name in ("compare.json", "compare_traces.png", "compare_residuals.png")]
        files += [folder / f"{Path(log).stem}_predicted.parquet" for log in args[2:] if log.endswith((".parquet", ".csv"))]
    elif command == "generate":
        files += [folder / name for name in DATASET_FILES[: 2 if "--no-plots" in args else None]]
    elif command == "train":
        files += [folder / name for name in ("model.json", "weights.npz", "checkpoint.npz") + (() if "--no-plots" in args else ("training_curve.png",))]
    elif command == "evaluate" and folder is not None:
        files.append(folder / "evaluation.json")
    elif command == "design" and "--no-plots" not in args:
        stem = Path(output).with_suffix("")
        files += [Path(f"{stem}_{kind}") for kind in ("report.json", "layouts.png", "convergence.png", "error_map.png")]
    elif command == "demo":
        files += [folder / name for name in ("summary.json", "demo_log.parquet", "truth_material.json", "fit/material.json", "fit/traces.png")]
    return files


FENCE = re.compile(r"^(`{3,})\s*([^\s`]*)(.*)$")
TITLE = re.compile(r"""title=["']([^"']+)["']""")


def read_steps(text):
    """A page's steps in order: ("file", name, content) for a titled block and
    ("run", argv) for each `$ hydrotact` line of a console block."""
    steps, lines, k = [], text.splitlines(), 0
    while k < len(lines):
        match = FENCE.match(lines[k].strip())
        if not match:
            k += 1
            continue
        fence, language, info = match.groups()
        end = next(j for j in range(k + 1, len(lines)) if lines[j].strip() == fence)
        body = lines[k + 1:end]
        title = TITLE.search(info)
        if title:
            steps.append(("file", title.group(1), "\n".join(body) + "\n"))
        elif language == "console":
            joined = "\n".join(body).replace("\\\n", " ")
            for line in joined.splitlines():
                if line.startswith("$ "):
                    argv = shlex.split(line[2:])
                    assert argv[0] == "hydrotact", f"a console line that is not hydrotact: {line}"
                    steps.append(("run", argv[1:]))
        k = end + 1
    return steps


def tour_text():
    readme = (ROOT / "README.md").read_text()
    start = readme.index("\n## A tour")
    end = readme.find("\n## ", start + 1)
    return readme[start:end if end > 0 else None]


def run_page(text, folder, monkeypatch, capsys):
    from hydrotact.cli import main

    monkeypatch.chdir(folder)
    ran = 0
    for step in read_steps(text):
        if step[0] == "file":
            (folder / step[1]).write_text(step[2])
            continue
        args = _shrink(step[1])
        started = time.process_time()
        try:
            code = main(args)
        except SystemExit as exit_:
            code = exit_.code
        if os.environ.get("HYDROTACT_DOCS_TIMES"):  # a file to append each command's CPU seconds to (for trimming the budget)
            with open(os.environ["HYDROTACT_DOCS_TIMES"], "a") as times:
                times.write(f"{time.process_time() - started:7.1f} s  hydrotact {shlex.join(args)}\n")
        captured = capsys.readouterr()
        assert code in (0, None), f"hydrotact {shlex.join(args)} exited {code}:\n{captured.err[-3000:]}"
        for path in _outputs(args):
            assert (folder / path).exists(), f"hydrotact {shlex.join(args)} did not write {path}"
        ran += 1
    return ran


@pytest.mark.parametrize("page", PAGES)
def test_the_commands_of_a_page_run_in_order(page, tmp_path, monkeypatch, capsys):
    assert run_page((DOCS / page).read_text(), tmp_path, monkeypatch, capsys) > 0


def test_the_commands_of_the_readme_tour_run(tmp_path, monkeypatch, capsys):
    assert run_page(tour_text(), tmp_path, monkeypatch, capsys) > 0


def test_every_console_command_is_a_hydrotact_command():
    """No page hides a shell command the test would not run (other shell lines go in
    ```shell blocks, which say what they need)."""
    for path in sorted(DOCS.glob("*.md")):
        for step in read_steps(path.read_text()):  # asserts on any other console line
            if step[0] == "run":
                assert step[1], path


def _public_names(stage):
    """A stage package's public names: its `__all__`, else its explicit re-exports
    (`from ._x import name as name`)."""
    tree = ast.parse((ROOT / "hydrotact" / stage / "__init__.py").read_text())
    names = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(target, "id", None) == "__all__" for target in node.targets):
            return list(ast.literal_eval(node.value))
        if isinstance(node, ast.ImportFrom):
            names += [alias.name for alias in node.names if alias.asname == alias.name]
    return names


def test_the_api_overview_names_every_public_name():
    import importlib

    api = (DOCS / "api.md").read_text()
    missing = []
    for stage in STAGES:
        assert f"## `hydrotact.{stage}`" in api, stage
        module = importlib.import_module(f"hydrotact.{stage}")
        for name in getattr(module, "__all__", None) or _public_names(stage):
            if f"`{name}`" not in api:
                missing.append(f"hydrotact.{stage}.{name}")
    assert not missing, f"docs/api.md never names {missing}"


def test_every_page_is_linked_from_the_index_and_the_readme():
    index = (DOCS / "README.md").read_text()
    pages = sorted(path.name for path in DOCS.glob("*.md") if path.name != "README.md")
    assert set(PAGES) < set(pages)
    for name in pages:
        assert f"]({name})" in index, f"docs/README.md does not link {name}"
    readme = (ROOT / "README.md").read_text()
    assert "](docs/README.md)" in readme
    for name in pages:
        assert f"](docs/{name})" in readme, f"README.md does not link docs/{name}"
    for image in re.findall(r"\]\(((?:docs|experiments)/[^)]+\.png)\)", readme):
        if "layout_design" not in image:  # experiments/layout_design.py writes its picture later
            assert (ROOT / image).is_file(), image
