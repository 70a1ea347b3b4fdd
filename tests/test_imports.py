"""The layering rule: no stage imports the command line or the pictures.

Every module under the stage packages is read with `ast` (not imported), so imports
inside functions count too, absolute or relative.
"""

import ast
from pathlib import Path

import pytest

import hydrotact

PACKAGE = Path(hydrotact.__file__).parent
STAGES = ("mesh", "field", "contact", "taxel", "visco", "sim", "sysid", "data", "sensors")
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
