"""Benchmark: sensor frames per second (contact surface + taxel sampling), culled
against brute-force Moller-Trumbore in the same run.

Cases: pad5x5 (25 disk taxels) pressed by the 2 mm cylinder, with 16 and 64 rays per
taxel; sphere8 (8 cone taxels) pressed by a half-space, 64 rays. Unit-modulus
Laplace field, float64. Poses sweep the probe across the sensor at a fixed depth.

- culled: `calc_unit_response` (contact + culled taxel sampling + wrench) for a batch
  of poses in one jitted call (vmap over chunks of poses, lax.map over chunks: the
  library's CPU_POSE_GROUP on a CPU, the whole batch on an accelerator);
- brute force: the same with every ray of every taxel tested against every triangle
  of the contact surface's buffer; run on fewer frames (it is slow), frames/s are
  per frame and comparable;
- contact only: the contact surface and its wrench alone, to show what the taxels add.

Timings are medians of repeats after compilation. Run:
`.venv/bin/python benchmarks/taxel.py [--batches 1 4096] [--brute-frames 16]`.
"""

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _machine import describe_machine, time_over_poses, write_results  # noqa: E402

from hydrotact.contact import (  # noqa: E402
    CPU_POSE_GROUP,
    HalfSpace,
    calc_contact_surface,
    compute_contact_surface,
    make_cylinder_probe,
    make_pose,
)
from hydrotact.sim import SimCapacity, make_sensor_model  # noqa: E402
from hydrotact.taxel import calc_taxel_pressures, sample_taxels  # noqa: E402


def _poses(sensor, count):
    if sensor == "pad5x5":
        x = np.linspace(-4.4e-3, 4.4e-3, count)
        return np.column_stack([x, 0.3 * x, np.full(count, 4e-3 - 0.45e-3)])
    x = np.linspace(-3e-3, 3e-3, count)
    return np.column_stack([x, -0.5 * x, np.full(count, 15e-3 - 1e-3)])


def _frames_per_second(frame, translations, repeats):
    chunk = CPU_POSE_GROUP if jax.default_backend() == "cpu" else len(translations)
    seconds, result = time_over_poses(frame, translations, chunk, repeats)
    return len(translations) / seconds, result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 4096])
    parser.add_argument("--brute-frames", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    machine = describe_machine()
    print(f"machine: {machine}")
    print("| case | rays/taxel | batch | culled frames/s | brute-force frames/s | culled/brute | contact-only frames/s | max abs diff (Pa per Pa of E) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    rows = []
    cases = [("pad5x5", make_cylinder_probe(2e-3), 16), ("pad5x5", make_cylinder_probe(2e-3), 64), ("sphere8", HalfSpace(), 64)]
    for sensor, probe, rays in cases:
        model = make_sensor_model(sensor, num_rays=rays)
        probe_name = "2 mm cylinder" if sensor == "pad5x5" else "half-space"
        sample = jax.vmap(make_pose)(jnp.asarray(_poses(sensor, 64)))
        surfaces, contact_capacity = compute_contact_surface(model.field, probe, sample, clusters=model.clusters)
        _, taxel_pairs = sample_taxels(model.layout, surfaces, rays)
        capacity = SimCapacity.of(contact_capacity, taxel_pairs)

        def culled(translation, model=model, probe=probe, capacity=capacity, rays=rays):
            surface = calc_contact_surface(model.field, probe, make_pose(translation), capacity.contact, model.clusters)
            readings = calc_taxel_pressures(model.layout, surface, rays, capacity.taxel)
            return readings.pressures, surface.calc_force(), surface.did_overflow | readings.did_overflow

        def brute(translation, model=model, probe=probe, capacity=capacity, rays=rays):
            surface = calc_contact_surface(model.field, probe, make_pose(translation), capacity.contact, model.clusters)
            readings = calc_taxel_pressures(model.layout, surface, rays, brute_force=True)
            return readings.pressures, surface.calc_force(), surface.did_overflow

        def contact_only(translation, model=model, probe=probe, capacity=capacity):
            surface = calc_contact_surface(model.field, probe, make_pose(translation), capacity.contact, model.clusters)
            return surface.calc_wrench(), surface.did_overflow

        brute_translations = jnp.asarray(_poses(sensor, args.brute_frames))
        brute_rate, brute_result = _frames_per_second(brute, brute_translations, 1)
        culled_check = jax.jit(jax.vmap(culled))(brute_translations)[0]
        difference = float(jnp.max(jnp.abs(culled_check - brute_result[0].reshape(culled_check.shape))))
        for batch in args.batches:
            translations = _poses(sensor, batch)
            rate, result = _frames_per_second(culled, translations, args.repeats if batch < 1024 else 1)
            assert not bool(jnp.any(result[2])), "capacity too small for the benchmark poses"
            contact_rate, _ = _frames_per_second(contact_only, translations, args.repeats if batch < 1024 else 1)
            row = {
                "case": f"{sensor} + {probe_name}",
                "rays_per_taxel": rays,
                "num_taxels": model.num_taxels,
                "batch": batch,
                "taxel_pair_capacity": capacity.taxel_pairs,
                "contact_pair_capacity": capacity.contact.pairs,
                "culled_frames_per_s": rate,
                "brute_frames_per_s": brute_rate,
                "brute_frames_measured": args.brute_frames,
                "ratio": rate / brute_rate,
                "contact_only_frames_per_s": contact_rate,
                "max_abs_difference": difference,
            }
            rows.append(row)
            print(
                f"| {row['case']} | {rays} | {batch} | {rate:,.1f} | {brute_rate:,.2f} | {rate / brute_rate:,.1f} | {contact_rate:,.1f} | {difference:.1e} |",
                flush=True,
            )
    print(f"written: {write_results('taxel', machine, rows)}")


if __name__ == "__main__":
    main()
