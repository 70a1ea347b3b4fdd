"""The `hydrotact` command line and the demo job."""

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import box_surface, run_cli

from hydrotact.field import DEFAULT_MODULUS
from hydrotact.mesh import CORE, read_mesh


def test_help_lists_the_commands():
    result = run_cli("--help")
    assert result.returncode == 0
    for command in ("mesh", "field", "demo"):
        assert command in result.stdout


def test_mesh_command_reports_and_writes(tmp_path):
    vtu, vtk, png = tmp_path / "pad.vtu", tmp_path / "pad.vtk", tmp_path / "pad.png"
    result = run_cli("mesh", "pad5x5", "--edge-length", "1e-3", "-o", vtu, "--vtk", vtk, "--png", png, "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["num_tets"] == 6 * 14 * 14 * 4
    assert report["min_dihedral_deg"] > 30 and report["worst_aspect_ratio"] < 2
    mesh, _ = read_mesh(vtu)
    assert mesh.num_tets == report["num_tets"]
    assert np.sum(np.asarray(mesh.face_tags) == CORE) == report["num_core_faces"]
    assert vtk.read_text().startswith("# vtk DataFile Version")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_mesh_command_on_a_surface_file_in_millimetres(tmp_path):
    path = tmp_path / "block.stl"
    surface = box_surface((6.0, 6.0, 3.0))  # millimetres
    surface.export(path)
    result = run_cli("mesh", path, "--units", "mm", "--edge-length", "1", "--json")  # --edge-length in --units too
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    np.testing.assert_allclose(report["volume_m3"], 108e-9, rtol=1e-3)
    np.testing.assert_allclose(report["core_area_m2"], 36e-6, rtol=1e-3)


def test_field_command(tmp_path):
    output, png = tmp_path / "field.vtu", tmp_path / "field.png"
    result = run_cli("field", "ellipsoid8", "--modulus", "2e5", "-o", output, "--png", png, "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["kind"] == "laplace" and report["dtype"] == "float64"
    assert report["residual_norm"] < 1e-9
    assert report["min_strain"] == 0.0 and report["max_strain"] == 1.0
    assert report["max_pressure_Pa"] == 2e5
    _, data = read_mesh(output)
    np.testing.assert_allclose(data["pressure_Pa"], 2e5 * data["strain"])
    assert png.stat().st_size > 10_000

    distance = json.loads(run_cli("field", output, "--kind", "distance", "--json").stdout)
    assert distance["kind"] == "distance" and distance["residual_norm"] is None
    np.testing.assert_allclose(distance["max_strain"], 1.0, rtol=1e-15)


def test_demo_fits_back_its_material(tmp_path):
    """The demo at smoke size: simulate a viscoelastic pad5x5 log with barometer
    noise, fit it back; the truth lies within 1 % (E) and 5 % (τ) and the report,
    material and pictures are where the summary says."""
    result = run_cli("demo", "--smoke", "-o", tmp_path / "out")
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    truth, fit = summary["truth"], summary["fit"]
    assert fit["converged"] and fit["num_terms"] == len(truth["taus"])
    np.testing.assert_allclose(fit["long_term_modulus_Pa"]["value"], truth["long_term_modulus"], rtol=0.01)
    for term, modulus, tau in zip(fit["prony_terms"], truth["moduli"], truth["taus"]):
        np.testing.assert_allclose(term["modulus_Pa"]["value"], modulus, rtol=0.05)
        np.testing.assert_allclose(term["tau_s"]["value"], tau, rtol=0.05)
    assert 0.8 < fit["reduced_chi_square"] < 1.2
    for path in summary["files"].values():
        assert (tmp_path / "out").as_posix() in path
        head = Path(path).read_bytes()[:4]
        assert head in (b"\x89PNG", b"{\n  ", b"PAR1") or path.endswith(".csv"), path
    assert "summary.json" in result.stdout and "truth" in result.stdout


def test_contact_command(tmp_path):
    png = tmp_path / "contact.png"
    result = run_cli("contact", "--sensor", "pad5x5", "--field", "distance", "--probe", "cylinder:d=2mm", "--at", "0,2.2mm,0.4mm", "--json", "--png", png)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    np.testing.assert_allclose(report["tip_position_m"], [0.0, 2.2e-3, 3.6e-3], atol=1e-15)
    # The tip face (a 48-gon inscribed in the 1 mm circle) and the walls 0.4 mm deep.
    tip_area = 0.5 * 48 * (1e-3) ** 2 * np.sin(2 * np.pi / 48)
    wall_area = 48 * 2 * 1e-3 * np.sin(np.pi / 48) * 0.4e-3
    np.testing.assert_allclose(report["area_m2"], tip_area + wall_area, rtol=1e-9)
    assert report["force_N"][2] < 0 and abs(report["force_N"][0]) < 1e-3 * abs(report["force_N"][2])
    np.testing.assert_allclose(report["centroid_m"][:2], [0.0, 2.2e-3], atol=1e-9)
    assert report["modulus_Pa"] == DEFAULT_MODULUS == 1e6  # the default when --modulus is left out
    assert 0 < report["max_pressure_Pa"] <= DEFAULT_MODULUS
    assert png.stat().st_size > 10_000

    plane = json.loads(run_cli("contact", "--sensor", "sphere8", "--probe", "plane", "--at", "0,0,1mm", "--json").stdout)
    assert plane["num_polygons"] > 100 and plane["force_N"][2] < 0


def test_contact_render_of_a_sphere_probe_on_the_sphere(tmp_path):
    """The command a newcomer tried: a sphere probe (no feature edges to outline) on
    sphere8, drawn to PNG; the report is printed first, whatever the render does."""
    png = tmp_path / "c.png"
    result = run_cli("contact", "--sensor", "sphere8", "--probe", "sphere:r=3mm", "--at", "1mm,0,0.5mm", "--png", png, "--json")
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    report = json.loads(result.stdout)
    assert report["num_polygons"] > 50 and report["force_N"][2] < 0 and report["max_pressure_Pa"] > 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


@pytest.mark.parametrize(("span", "step"), [(13.2, 2.5), (4.0, 1.0), (20.0, 5.0), (32.0, 10.0), (0.6, 0.1), (1.1, 0.2), (6.0, 1.0)])
def test_render_axes_take_round_steps(span, step):
    from hydrotact.viz._render import _nice_step

    assert _nice_step(span) == pytest.approx(step)  # the smallest of 1, 2, 2.5, 5 x 10^k with at most 6 steps over the span


def test_every_option_of_every_command_is_documented():
    """--help says what each option does (none shows a bare flag), and the command
    reference (docs/cli.md, its synopsis) names each command's options."""
    import argparse

    from hydrotact.cli import make_parser

    reference = (Path(__file__).parents[1] / "docs" / "cli.md").read_text()
    commands = next(action for action in make_parser()._actions if isinstance(action, argparse._SubParsersAction))
    assert len(commands.choices) >= 7
    for name, parser in commands.choices.items():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction) or not action.option_strings:
                continue
            assert action.help, f"hydrotact {name} {action.option_strings[-1]} has no help text"
            longest = max(action.option_strings, key=len)
            assert longest in reference or (longest == "--output" and "-o " in reference), f"docs/cli.md never names hydrotact {name} {longest}"


def test_a_stalled_computation_ends_with_one_line_naming_what_it_waited_for(tmp_path):
    """A command whose computation stops using the CPU (XLA's runtime waiting for a
    wakeup that never comes, here a sleep in its place) ends after HYDROTACT_STALL_S
    with one line and exit status 3; a busy one is left alone."""
    import os
    import subprocess
    import sys
    import time

    from hydrotact._stall import StallGuard, doing

    script = (
        "import time, hydrotact.cli as cli\n"
        "from hydrotact._stall import doing\n"
        "def run(args):\n"
        "    doing('the lumped fit\\'s solve (3 Prony terms, start 1 of at most 3)')\n"
        "    time.sleep(60)\n"
        "cli.fit.run = run\n"
        f"raise SystemExit(cli.main(['fit', 'log.parquet', '-o', {str(tmp_path / 'out')!r}]))\n"
    )
    started = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=os.environ | {"HYDROTACT_STALL_S": "2"})
    assert result.returncode == 3, result.stderr
    assert result.stderr.count("\n") == 1 and "stuck: no CPU used for" in result.stderr and "the lumped fit's solve (3 Prony terms" in result.stderr
    assert time.perf_counter() - started < 45
    stalls = []
    doing("a busy loop")
    with StallGuard(lambda what, seconds: stalls.append(what), limit_s=0.5, poll_s=0.05):
        end = time.perf_counter() + 1.5
        while time.perf_counter() < end:
            pass
    assert stalls == []
    with StallGuard(lambda what, seconds: stalls.append((what, seconds)), limit_s=0.5, poll_s=0.05):
        time.sleep(1.5)
    assert len(stalls) == 1 and stalls[0][0] == "a busy loop" and stalls[0][1] >= 0.5

