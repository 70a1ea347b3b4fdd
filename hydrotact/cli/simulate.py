"""`hydrotact simulate`: simulate a sensor along a probe trajectory; write a barometer log.

Long trajectories are simulated in blocks; each finished block is saved beside the
output (`.LOG.partial.npz`, atomically), so an interrupted run resumes where it
stopped when started again with the same inputs. The log itself is written atomically
at the end, and the partial file removed.
"""

import warnings
from pathlib import Path

import numpy as np

from .._defaults import DEFAULT_MODULUS
from .._errors import HydrotactError, HydrotactWarning
from .._files import check_output
from .._units import LENGTH_UNITS
from ._arguments import MODULUS_HELP, number
from ._output import print_report


def add_parser(subparsers):
    parser = subparsers.add_parser("simulate", help="simulate a sensor along a probe trajectory; write a barometer log")
    parser.add_argument("--sensor", required=True, metavar="S", help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a sensor JSON file")
    parser.add_argument("--probe", required=True, metavar="SPEC", help="cylinder:d=2mm[,length=10mm], sphere:r=3mm or plane")
    parser.add_argument("--trajectory", required=True, type=Path, metavar="TRAJ.csv", help="CSV with columns time (s), x, y, z (probe tip, --units) and optionally rx, ry, rz (rad)")
    parser.add_argument("--units", default="m", choices=list(LENGTH_UNITS), help="length unit of the trajectory's x, y, z (default m)")
    parser.add_argument("--modulus", type=number, default=DEFAULT_MODULUS, metavar="E", help=MODULUS_HELP)
    parser.add_argument("--material", type=Path, metavar="MATERIAL.json", help="a viscoelastic material (Prony series; e.g. from hydrotact fit); overrides --modulus")
    parser.add_argument("--barometer", action="store_true", help="write absolute barometer readings (the sensor's part: ambient, LSB, noise, rate) instead of elastomer pressures")
    parser.add_argument("--seed", type=int, default=0, help="seed of the barometer noise and channel spreads (default 0)")
    parser.add_argument("--noise", type=number, metavar="PA", help="barometer RMS noise in Pa (default: the part's)")
    parser.add_argument("--gain-spread", type=number, default=0.0, metavar="S", help="std. dev. of the channel gains around 1 (default 0)")
    parser.add_argument("--offset-spread", type=number, default=0.0, metavar="PA", help="std. dev. of the channel offsets in Pa (default 0)")
    parser.add_argument("--force-noise", type=number, default=0.0, metavar="N", help="load-cell RMS noise added to fx, fy, fz in N (default 0)")
    parser.add_argument("--field", default="laplace", choices=["laplace", "distance"], help="the sensor's strain field")
    parser.add_argument("--rays", type=int, default=64, metavar="N", help="rays per taxel receptive field (default 64)")
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="LOG.parquet", help="the log to write (Parquet)")
    parser.add_argument("--png", type=Path, metavar="LOG.png", help="plot the simulated traces")
    parser.add_argument("--force", action="store_true", help="write the log even if no sample touches the sensor (a no-load baseline log)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    report = run_simulate(
        args.sensor, args.probe, args.trajectory, args.output, modulus=args.modulus, material=args.material, barometer=args.barometer,
        seed=args.seed, noise_rms=args.noise, gain_spread=args.gain_spread, offset_spread=args.offset_spread, force_noise=args.force_noise, field=args.field,
        num_rays=args.rays, units=args.units, png=args.png, progress=not args.json, force=args.force,
    )
    print_report(f"simulated log of {report['sensor']}", report, args.json)


def checkpoint_path(output) -> Path:
    """Where a simulation writing `output` keeps its finished blocks."""
    output = Path(output)
    return output.with_name(f".{output.name}.partial.npz")


def run_simulate(
    sensor: str, probe_spec: str, trajectory_path, output, *, modulus=DEFAULT_MODULUS, material=None, barometer=False, seed=0, noise_rms=None,
    gain_spread=0.0, offset_spread=0.0, force_noise=0.0, field="laplace", num_rays=64, units="m", png=None, progress=True, force=False,
) -> dict:
    """Simulate the sensor along the trajectory file and write the log (and plot).

    With `material` (a material.json), the material is viscoelastic; with `barometer`,
    the log holds absolute barometer readings (sim.BarometerSettings). Everything is
    read and checked before the simulation: the outputs, the sensor, the probe, the
    material, and that the trajectory comes near the sensor (sim.check_reach). A
    simulation in which no sample touches is refused unless `force` (a no-load log).
    Returns a report dict."""
    from ..contact import parse_probe
    from ..data import material_prony, read_material
    from ..field import check_modulus
    from ..sensors import load_sensor
    from ..sim import BarometerSettings, check_reach, read_trajectory, simulate_log
    from ..visco import make_prony

    output = check_output(output, suffixes=(".parquet",), what="the log")
    if png is not None:
        check_output(png, suffixes=(".png",), what="the plot")
    settings = None
    if barometer:
        settings = BarometerSettings(seed=seed, noise_rms=noise_rms, gain_spread=gain_spread, offset_spread=offset_spread, force_noise=force_noise)
    else:
        options = (("--noise", noise_rms), ("--gain-spread", gain_spread or None), ("--offset-spread", offset_spread or None), ("--force-noise", force_noise or None))
        given = [flag for flag, value in options if value is not None]
        if given:
            raise HydrotactError(f"{given[0]}: applies to barometer readings; add --barometer")
    if material is not None:
        material = material_prony(read_material(material), str(material))
    else:
        material = make_prony(check_modulus(modulus), source="--modulus")
    spec = load_sensor(sensor)
    probe = parse_probe(probe_spec)
    if not isinstance(num_rays, int) or num_rays < 1:
        raise HydrotactError(f"--rays: rays per taxel must be a positive whole number, got {num_rays!r}")
    trajectory = read_trajectory(trajectory_path, units=units)
    check_reach(spec, probe, trajectory, str(trajectory_path))
    partial = checkpoint_path(output)
    log, samples = simulate_log(spec, probe, trajectory, material, field_kind=field, num_rays=num_rays, barometer=settings, progress=progress, checkpoint=partial)
    touched = np.any(np.asarray(samples.normal_force) > 0.0) or np.any(np.asarray(samples.taxel_pressures) > 0.0)
    if not force and not touched:
        partial.unlink(missing_ok=True)  # nothing of a refused run stays (its responses are cached: --force reruns at once)
        raise HydrotactError(
            f"{trajectory_path}: no sample touches the sensor (no force, no pressure at any barometer): nothing written; "
            "is the trajectory in the sensor's frame and unit (--units)? Add --force for a no-load log"
        )
    report = write_simulated_log(log, samples, output, png)
    partial.unlink(missing_ok=True)
    saturated = log.metadata.get("barometer", {}).get("saturated_samples", [])
    if any(saturated):
        low, high = log.metadata["barometer"]["range_Pa"]
        warnings.warn(HydrotactWarning(
            f"{output}: {sum(saturated)} readings on {sum(1 for n in saturated if n)} channels reached the {spec.part.name}'s range, {low:g}-{high:g} Pa, "
            "and read its limit (as the part does; barometer.saturated_samples in the log; fit masks them): press less deep, or the skin is softer than simulated"
        ), stacklevel=2)
    return report


def write_simulated_log(log, samples, output, png=None) -> dict:
    """Write a simulated log (Parquet) and, with `png`, the plot of its traces;
    returns the report `hydrotact simulate` prints."""
    from ..data import write_log

    write_log(output, log)
    probe = log.metadata.get("probe", "")
    if png is not None:
        from ..viz import plot_log

        plot_log(log, png, title=f"{log.metadata['sensor']}: {probe}, E(0) = {float(samples.modulus):g} Pa")
    return {
        "sensor": log.metadata["sensor"],
        "probe": probe,
        "num_samples": log.num_samples,
        "num_taxels": len(log.metadata["channels"]),
        "samples_in_contact": int(np.sum(samples.contact)),
        "max_normal_force_N": float(np.max(samples.normal_force, initial=0.0)),
        "max_taxel_pressure_Pa": float(np.max(samples.taxel_pressures, initial=0.0)),
        **({"saturated_readings": sum(log.metadata["barometer"]["saturated_samples"])} if "barometer" in log.metadata else {}),
        "log": str(output),
        **({"png": str(png)} if png is not None else {}),
    }
