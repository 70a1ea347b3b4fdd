"""The `hydrotact simulate` job: a sensor, a probe and a trajectory file -> a barometer
log (Parquet) and a plot of its traces.

Long trajectories are simulated in blocks; each finished block is saved beside the
output (`.LOG.partial.npz`, atomically), so an interrupted run resumes where it
stopped when started again with the same inputs. The log itself is written atomically
at the end, and the partial file removed.
"""

from pathlib import Path

import numpy as np

from ._errors import HydrotactError


def checkpoint_path(output) -> Path:
    """Where a simulation writing `output` keeps its finished blocks."""
    output = Path(output)
    return output.with_name(f".{output.name}.partial.npz")


def run_simulate(sensor: str, probe_spec: str, trajectory_path, output, *, modulus=1e6, material=None, barometer=False, seed=0, noise_rms=None, gain_spread=0.0, offset_spread=0.0, force_noise=0.0, field="laplace", num_rays=64, units="m", png=None, progress=True) -> dict:
    """Simulate the sensor along the trajectory file and write the log (and plot).

    With `material` (a material.json), the material is viscoelastic; with `barometer`,
    the log holds absolute barometer readings (sim.BarometerSettings). Returns a
    report dict."""
    from .data import material_prony, read_material, write_log
    from .sim import BarometerSettings, read_trajectory, simulate_log
    from .visco import make_prony

    output = Path(output)
    if output.suffix.lower() != ".parquet":
        raise HydrotactError(f"{output}: the log is written as Parquet; name it *.parquet")
    if png is not None and Path(png).suffix.lower() != ".png":
        raise HydrotactError(f"{png}: the plot is written as PNG; name it *.png")
    settings = None
    if barometer:
        settings = BarometerSettings(seed=seed, noise_rms=noise_rms, gain_spread=gain_spread, offset_spread=offset_spread, force_noise=force_noise)
    else:
        given = [flag for flag, value in (("--noise", noise_rms), ("--gain-spread", gain_spread or None), ("--offset-spread", offset_spread or None), ("--force-noise", force_noise or None)) if value is not None]
        if given:
            raise HydrotactError(f"{given[0]}: applies to barometer readings; add --barometer")
    if material is not None:
        material = material_prony(read_material(material), str(material))
    else:
        material = make_prony(modulus, source="--modulus")
    trajectory = read_trajectory(trajectory_path, units=units)
    partial = checkpoint_path(output)
    log, samples = simulate_log(sensor, probe_spec, trajectory, material, field_kind=field, num_rays=num_rays, barometer=settings, progress=progress, checkpoint=partial)
    write_log(output, log)
    partial.unlink(missing_ok=True)
    if png is not None:
        from .viz import plot_log

        plot_log(log, png, title=f"{log.metadata['sensor']}: {probe_spec}, E(0) = {float(material.instantaneous_modulus):g} Pa")
    return {
        "sensor": log.metadata["sensor"],
        "probe": probe_spec,
        "num_samples": log.num_samples,
        "num_taxels": len(log.metadata["channels"]),
        "samples_in_contact": int(np.sum(samples.contact)),
        "max_normal_force_N": float(np.max(samples.normal_force, initial=0.0)),
        "max_taxel_pressure_Pa": float(np.max(samples.taxel_pressures, initial=0.0)),
        "log": str(output),
        **({"png": str(png)} if png is not None else {}),
    }
