"""The layering rule: no stage imports the command line or the pictures.

Every module under the stage packages is read with `ast` (not imported), so imports
inside functions count too, absolute or relative.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import hydrotact

PACKAGE = Path(hydrotact.__file__).parent
STAGES = ("mesh", "field", "contact", "taxel", "elastic", "visco", "sim", "sysid", "data", "sensors", "datasets", "models", "design")
FORBIDDEN = ("hydrotact.cli", "hydrotact.viz")


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported_modules(path: Path, source: str | None = None):
    """(line, absolute module name) of every import in the file (or in `source`, read
    as that file), `from X import y` giving both X and X.y (y may be a module)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    source = path.read_text() if source is None else source
    for node in ast.walk(ast.parse(source, filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            yield node.lineno, module
            for alias in node.names:
                yield node.lineno, f"{module}.{alias.name}"


def _is_forbidden(module: str) -> bool:
    return any(module == bad or module.startswith(bad + ".") for bad in FORBIDDEN)


def _stage_files():
    return sorted(path for stage in STAGES for path in (PACKAGE / stage).rglob("*.py"))


def test_every_stage_is_checked():
    for stage in STAGES:
        assert (PACKAGE / stage / "__init__.py").is_file(), stage
    assert len(_stage_files()) > 30


@pytest.mark.parametrize("stage", STAGES)
def test_no_stage_imports_cli_or_viz(stage):
    offenders = [
        f"{path.relative_to(PACKAGE.parent)}:{line}: {module}"
        for path in sorted((PACKAGE / stage).rglob("*.py"))
        for line, module in _imported_modules(path)
        if _is_forbidden(module)
    ]
    assert not offenders, "a stage imports the command line or viz:\n" + "\n".join(offenders)


def test_the_lumped_model_imports_nothing_private_from_its_parent():
    """hydrotact.sysid.lumped takes what it shares with the simulator fit from
    hydrotact.sysid.shared (public names), never a private module or name of sysid."""
    lumped = PACKAGE / "sysid" / "lumped"
    offenders = []
    for path in sorted(lumped.rglob("*.py")):
        for line, module in _imported_modules(path):
            if module.startswith("hydrotact.sysid.") and not module.startswith("hydrotact.sysid.lumped"):
                if any(part.startswith("_") for part in module.split(".")[2:]):
                    offenders.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {module}")
    assert not offenders, "the lumped package reaches into its parent:\n" + "\n".join(offenders)
    assert len(list(lumped.glob("_*.py"))) >= 10
    # Importing sysid shows the lumped model as one sub-package, none of its modules.
    shown = subprocess.run(
        [sys.executable, "-c", "import hydrotact.sysid as s; print(' '.join(n for n in dir(s) if not n.startswith('__')))"],
        capture_output=True, text=True, check=True,
    ).stdout.split()
    assert "lumped" in shown and "fit_press_logs" in shown and "LumpedFit" in shown
    assert not [name for name in shown if name.startswith(("_press", "_lumped", "_compare", "_prediction", "_presses"))], shown


def test_the_checker_sees_relative_and_nested_imports():
    source = (
        "from ._fit import FitResult\n"
        "from hydrotact.vizier import x\n"
        "def f():\n"
        "    from ..viz import save_figure\n"
        "    from .. import cli\n"
        "    import hydrotact.cli.fit\n"
    )
    modules = [module for _, module in _imported_modules(PACKAGE / "sysid" / "_example.py", source)]
    assert "hydrotact.sysid._fit" in modules
    assert [m for m in modules if _is_forbidden(m)] == ["hydrotact.viz", "hydrotact.viz.save_figure", "hydrotact.cli", "hydrotact.cli.fit"]
    sub_package = [module for _, module in _imported_modules(PACKAGE / "mesh" / "__init__.py", "from ..viz import render_mesh\n")]
    assert sub_package == ["hydrotact.viz", "hydrotact.viz.render_mesh"]


# --- what the notebooks may use, and what importing the pictures leaves alone ---------

NOTEBOOKS = sorted((PACKAGE.parent / "notebooks").glob("[0-9]*.py"))


def _public_names(module_name: str) -> set[str]:
    """The names a package's `__init__.py` re-exports (`from ._x import y as y`) or
    defines, none private."""
    path = PACKAGE.parent.joinpath(*module_name.split(".")) / "__init__.py"
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom):
            names |= {alias.asname for alias in node.names if alias.asname == alias.name}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names |= {target.id for target in node.targets if isinstance(target, ast.Name)}
    return {name for name in names if not name.startswith("_")}


def _private_uses(path: Path, source: str | None = None) -> list[str]:
    """`line: module.name` for every hydrotact import of the file that is not public:
    a private module, or a name its package does not re-export."""
    found = []
    source = path.read_text() if source is None else source
    for node in ast.walk(ast.parse(source, filename=str(path))):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno}: {alias.name}" for alias in node.names if alias.name.startswith("hydrotact") and "._" in alias.name]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("hydrotact"):
            if "._" in node.module or node.level:
                found.append(f"{node.lineno}: {node.module}")
                continue
            public = _public_names(node.module)
            found += [f"{node.lineno}: {node.module}.{alias.name}" for alias in node.names if alias.name not in public]
    return found


def test_the_notebooks_use_only_the_public_api():
    assert NOTEBOOKS
    offenders = [f"{path.name}:{use}" for path in NOTEBOOKS for use in _private_uses(path)]
    assert not offenders, "a notebook reaches past the public API:\n" + "\n".join(offenders)


def test_the_public_api_checker_sees_private_uses():
    source = (
        "from hydrotact.sim import simulate_log, _cache_path\n"
        "from hydrotact.sysid._fit import FitResult\n"
        "from hydrotact.data import read_log\n"
        "import hydrotact.viz._plots\n"
        "from hydrotact.sysid import no_such_name\n"
    )
    assert _private_uses(NOTEBOOKS[0], source) == [
        "1: hydrotact.sim._cache_path", "2: hydrotact.sysid._fit", "4: hydrotact.viz._plots", "5: hydrotact.sysid.no_such_name",
    ]


def test_importing_the_pictures_keeps_the_users_matplotlib_backend(tmp_path):
    """A notebook's backend (inline, here 'svg' as a stand-in) survives `import
    hydrotact.viz` and a plot written through it, and pyplot keeps no figure of ours."""
    import os
    import subprocess
    import sys

    script = (
        "import matplotlib, matplotlib.pyplot as plt, numpy as np\n"
        "before = matplotlib.get_backend()\n"
        "import hydrotact.viz\n"
        "from sysid_synthetic import make_lumped_log\n"
        "from hydrotact.visco import make_prony\n"
        "log = make_lumped_log(make_prony(1.0, [0.5], [2.0]), [800.0], [1.5], duration=4.0, rate_hz=20.0)\n"
        f"hydrotact.viz.plot_log(log, {str(tmp_path / 'log.png')!r})\n"
        "assert matplotlib.get_backend() == before, (before, matplotlib.get_backend())\n"
        "print(before, len(plt.get_fignums()))\n"
    )
    env = {**os.environ, "MPLBACKEND": "svg", "PYTHONPATH": str(Path(__file__).parent)}
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["svg", "0"]
    assert (tmp_path / "log.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_schema_readme_names_the_schemas_there_are():
    """data_schemas/README.md lists every schema file, and no file that is not there."""
    import re

    folder = PACKAGE.parent / "data_schemas"
    named = set(re.findall(r"`([a-z_]+\.schema\.json)`", (folder / "README.md").read_text()))
    assert named == {path.name for path in folder.glob("*.schema.json")}
