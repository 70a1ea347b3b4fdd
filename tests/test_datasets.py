"""Synthetic datasets (hydrotact.datasets, `hydrotact generate`): the event sampler's
distributions, labels against the forward model, residual stress across events,
determinism, resumption after SIGKILL, several devices and Ray workers, refusals."""

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from hydrotact import HydrotactError
from hydrotact.datasets import (
    DatasetConfig,
    PoseEngine,
    draw_target_forces,
    find_touchable_skin,
    lay_out_timeline,
    load_dataset,
    march_presses,
    pressing_rotation_vectors,
    run_session,
    sample_events,
    sample_skin_points,
)
from hydrotact.sensors import load_sensor

# Smoke size: a handful of short events, 16 rays per receptive field, the regime's 3 mm
# sphere meshed coarsely (its contacts cost a fifth).
COARSE_SPHERE = "sphere:r=3mm,subdivisions=1"
ARGS = [
    "--sensor", "sphere8", "--probe", COARSE_SPHERE, "--events", "5", "--seed", "3", "--rays", "16", "--hold-range", "0.3,0.6", "--gap-range", "0.2,0.4",
    "--speed-range", "0.01,0.02", "--force-range", "0.2,2", "--noise", "0", "--gain-spread", "0.05", "--offset-spread", "100", "--shard-rows", "300",
]
# E(0) 8 MPa, near the generator's 10 MPa default: a softer skin (0.8 MPa was used here
# before) sinks deeper for the same force, so its smoke run took over twice as long
# (more approach samples to compute, each on larger contact buffers).
MATERIAL = {"long_term": 5e6, "moduli": [3e6], "taus": [2.0]}


@pytest.fixture(scope="module")
def material_file(tmp_path_factory):
    from hydrotact.data import make_material_document, write_material

    path = tmp_path_factory.mktemp("material") / "material.json"
    write_material(path, make_material_document(MATERIAL["long_term"], MATERIAL["moduli"], MATERIAL["taus"], covariance=np.diag([0.01, 0.04, 0.04])))
    return path


def _generate(output, material_file, *extra):
    from hydrotact.cli import main

    return main(["generate", *ARGS, "--material", str(material_file), "-o", str(output), "--json", *extra])


@pytest.fixture(scope="module")
def reference(tmp_path_factory, material_file):
    """The smoke dataset, generated in this process (with its plots)."""
    output = tmp_path_factory.mktemp("datasets") / "reference"
    assert _generate(output, material_file) == 0
    return output


def _shards(folder) -> dict:
    manifest = json.loads((Path(folder) / "manifest.json").read_text())
    return {entry["file"]: (Path(folder) / entry["file"]).read_bytes() for entry in manifest["shards"]}


# --- the sampler -------------------------------------------------------------------


def test_skin_points_are_uniform_by_area():
    """Points fall on area-equal patches of the touchable skin equally often (chi^2),
    lie on their triangles, and within the sensor's angle ranges."""
    spec = load_sensor("sphere8")
    skin = find_touchable_skin(spec, spec.make_mesh(check=False))
    from hydrotact.sim import calc_contact_angles

    theta, phi = (np.asarray(a) for a in calc_contact_angles(skin.corners.mean(axis=1), spec.contact_center_S))
    assert np.all((theta >= spec.theta_range[0]) & (theta <= spec.theta_range[1]) & (phi >= spec.phi_range[0]) & (phi <= spec.phi_range[1]))
    rng = np.random.default_rng(7)
    points, normals, faces = sample_skin_points(skin, 40_000, rng)
    # Patches of equal area: faces ordered by height, cut at equal cumulative area.
    order = np.argsort(skin.corners[:, :, 2].mean(axis=1))
    cumulative = np.cumsum(skin.areas[order]) / skin.area
    patch_of_face = np.empty(len(order), dtype=int)
    patch_of_face[order] = np.minimum((cumulative * 20).astype(int), 19)
    area_per_patch = np.bincount(patch_of_face, weights=skin.areas, minlength=20) / skin.area
    counts = np.bincount(patch_of_face[faces], minlength=20)
    assert stats.chisquare(counts, 40_000 * area_per_patch).pvalue > 1e-3
    # Uniform in (theta, phi) would not be: a sphere's patches near theta = ±45 deg are smaller.
    a, b, c = (skin.corners[faces, k] for k in range(3))
    offsets = np.einsum("ij,ij->i", points - a, np.cross(b - a, c - a))
    assert np.max(np.abs(offsets)) < 1e-18  # on the triangle's plane (m^3)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_target_forces_follow_the_configured_distribution():
    rng = np.random.default_rng(11)
    forces = draw_target_forces(DatasetConfig(events=1), 20_000, rng)
    low, high = DatasetConfig().force_range
    assert stats.kstest(np.log(forces), stats.uniform(np.log(low), np.log(high / low)).cdf).pvalue > 1e-3
    assert np.mean(forces < 0.5) > 0.45  # low forces over-sampled: half the events below 0.5 N of 8
    uniform = draw_target_forces(DatasetConfig(events=1, force_distribution="uniform", force_range=(1.0, 3.0)), 20_000, rng)
    assert stats.kstest(uniform, stats.uniform(1.0, 2.0).cdf).pvalue > 1e-3


def test_probe_presses_along_the_drawn_direction():
    from hydrotact.contact import make_pose

    rng = np.random.default_rng(2)
    directions = rng.standard_normal((50, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[0] = [0.0, 0.0, 1.0]  # antiparallel to R's -z: half a turn
    directions[1] = [0.0, 0.0, -1.0]  # upright: no turn
    for d, rv in zip(directions, pressing_rotation_vectors(directions)):
        np.testing.assert_allclose(np.asarray(make_pose(jnp.zeros(3), jnp.asarray(rv)).rotation) @ [0.0, 0.0, -1.0], d, atol=1e-12)


def test_tilts_stay_within_the_limit_and_fill_the_cone():
    spec = load_sensor("sphere8")
    skin = find_touchable_skin(spec, spec.make_mesh(check=False))
    plan = sample_events(skin, DatasetConfig(events=4000, max_tilt_deg=30.0), np.random.default_rng(5))
    inward = -plan.normals
    angles = np.arccos(np.clip(np.einsum("ij,ij->i", plan.directions, inward), -1, 1))
    np.testing.assert_allclose(angles, plan.tilts, atol=1e-9)
    assert angles.max() <= np.radians(30.0) + 1e-12
    # Uniform over the cone's solid angle: 1 - cos(tilt) is uniform.
    assert stats.kstest((1 - np.cos(angles)) / (1 - np.cos(np.radians(30.0))), "uniform").pvalue > 1e-3


def test_approach_thickness_is_the_elastomers_chord():
    """The thickness along each approach against closed forms: on sphere8 (a sphere of
    radius 10 mm centred 5 mm above the board z = 0) the chord from the skin point to
    the sphere or the board, whichever comes first; on pad5x5's top face 4 mm / cos(tilt).
    Each event's max depth is the smaller of max_depth and the fraction of it."""
    config = DatasetConfig(events=400, max_tilt_deg=30.0, max_depth=6e-3, max_depth_fraction=0.5)
    spec = load_sensor("sphere8")
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), config, np.random.default_rng(8))
    centre = np.array([0.0, 0.0, 5e-3])
    d, p = plan.directions, plan.points
    sphere = -2.0 * np.einsum("ij,ij->i", p - centre, d)
    board = np.where(d[:, 2] < 0.0, -p[:, 2] / np.minimum(d[:, 2], -1e-300), np.inf)
    np.testing.assert_allclose(plan.thickness, np.minimum(sphere, board), rtol=0.03, atol=0.2e-3)  # a mesh of 1.2 mm edges
    assert np.any(board < sphere) and np.any(sphere < board)  # both ways out occur
    np.testing.assert_array_equal(plan.max_depths, np.minimum(6e-3, 0.5 * plan.thickness))
    assert np.any(plan.max_depths < 6e-3) and np.any(plan.max_depths == 6e-3)

    spec = load_sensor("pad5x5")
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), config, np.random.default_rng(9))
    top = (plan.normals[:, 2] > 0.99) & np.all(np.abs(plan.points[:, :2]) < 6.6e-3 - 4e-3 * np.tan(np.radians(30.0)), axis=1)
    assert top.sum() > 50
    np.testing.assert_allclose(plan.thickness[top], 4e-3 / np.cos(plan.tilts[top]), rtol=1e-9)


def test_a_stage_presses_straight_down_on_the_up_facing_skin_within_its_ranges():
    """The stage regime on pad5x5 (a 13.2 mm square pad, 4 mm thick): every approach
    along -z, every point on the top face (z = 4 mm) within the x and y ranges, uniform
    by area there (each coordinate uniform over its range), the thickness the pad's
    4 mm; a range beside the pad is refused naming the option."""
    spec = load_sensor("pad5x5")
    skin = find_touchable_skin(spec, spec.make_mesh(check=False))
    config = DatasetConfig(events=2000, regime="stage", target="depth", stage_x_range=(-5e-3, 3e-3), stage_y_range=(-1e-3, 1e-3))
    plan = sample_events(skin, config, np.random.default_rng(11))
    np.testing.assert_array_equal(plan.directions, np.tile([0.0, 0.0, -1.0], (2000, 1)))
    np.testing.assert_allclose(plan.points[:, 2], 4e-3, atol=1e-12)
    np.testing.assert_allclose(plan.tilts, 0.0, atol=1e-7)
    np.testing.assert_allclose(plan.thickness, 4e-3, rtol=1e-9)
    x, y = plan.points[:, 0], plan.points[:, 1]
    assert x.min() >= -5e-3 and x.max() <= 3e-3 and y.min() >= -1e-3 and y.max() <= 1e-3
    assert stats.kstest((x + 5e-3) / 8e-3, "uniform").pvalue > 1e-3 and stats.kstest((y + 1e-3) / 2e-3, "uniform").pvalue > 1e-3
    assert np.all(np.isfinite(plan.target_depths)) and np.all(np.isnan(plan.target_forces))
    with pytest.raises(HydrotactError, match="--regime stage: no skin face faces up .* within --stage-x-range"):
        sample_events(skin, DatasetConfig(events=10, regime="stage", stage_x_range=(20e-3, 30e-3)), np.random.default_rng(0))
    with pytest.raises(HydrotactError, match="--stage-x-range: only a stage"):
        DatasetConfig(stage_x_range=(0.0, 1e-3))


def test_config_refuses_impossible_regimes():
    for kwargs, words in (
        ({"events": 0}, "--events"), ({"force_range": (5.0, 1.0)}, "--force-range"), ({"force_range": (0.0, 8.0)}, "LOW > 0"),
        ({"gain_spread": 0.5}, "--gain-spread"), ({"max_tilt_deg": 95.0}, "--max-tilt-deg"), ({"force_distribution": "normal"}, "--force-distribution"),
        ({"speed_range": (0.5, 0.6), "max_depth": 1e-3}, "--speed-range"), ({"target": "torque"}, "--target"),
        ({"depth_range": (2e-3, 1e-3)}, "--depth-range"), ({"target": "depth", "depth_range": (0.0, 0.0)}, "HIGH > 0"),
        ({"regime": "robot"}, "--regime"), ({"regime": "stage", "stage_y_range": (1e-3, -1e-3)}, "--stage-y-range"),
    ):
        with pytest.raises(HydrotactError, match=words):
            DatasetConfig(**kwargs)


# --- the dataset -------------------------------------------------------------------


def test_dataset_reads_back_with_its_split_and_plots(reference):
    dataset = load_dataset(reference)
    manifest = dataset.manifest
    assert manifest["num_events"] == 5 and len(manifest["shards"]) >= 2
    ranges = sorted(manifest["split"]["train"] + manifest["split"]["test"])
    assert ranges[0][0] == 0 and ranges[-1][1] == dataset.num_rows
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))  # contiguous, disjoint, everything
    assert manifest["split"]["test"]
    every = dataset.arrays("all")
    np.testing.assert_allclose(np.diff(every["time"]), 1.0 / manifest["rate_hz"], rtol=1e-9)
    assert set(np.unique(every["phase"])) == {0, 1, 2, 3}
    touching = every["contact"] == 1
    assert touching.any() and (~touching).any()
    np.testing.assert_array_equal(touching, np.linalg.norm(np.column_stack([every["fx"], every["fy"], every["fz"]]), axis=1) > 0.1)
    assert np.all(np.isnan(every["theta"][every["phase"] == 0]))
    for window in dataset.windows("test", length=20, stride=7):
        assert np.all(np.diff(window["time"]) > 0) and np.allclose(np.diff(window["time"]), 0.01)  # never across a block edge
    for name in ("coverage.png", "histograms.png", "channel_swing.png", "examples.png"):
        assert (reference / name).stat().st_size > 10_000
    std = np.asarray(manifest["statistics"]["channel_std_Pa"])
    np.testing.assert_allclose(std, every_std := np.std(np.column_stack([every[name] for name in dataset.channels]), axis=0), rtol=1e-9)
    assert np.all(every_std > 0)


def test_labels_agree_with_the_forward_model(reference):
    """The session's first two events again through sim.calc_simulation (every
    sample's pose from time 0, the material, the manifest's channel gains and offsets,
    no noise): the same labels and readings. A prefix of the session is a session of
    its own (the hereditary integral looks back only), and the second event carries
    the first's memory."""
    from hydrotact.contact import parse_probe
    from hydrotact.sim import SimCapacity, calc_simulation, make_sensor_model, make_trajectory
    from hydrotact.visco import make_barometer_signal, make_prony

    dataset = load_dataset(reference)
    manifest = dataset.manifest
    every = dataset.arrays("all")
    end = int(np.flatnonzero(every["event"] == 2)[0])  # the third event's first sample
    rows = {name: values[:end] for name, values in every.items() if name != "block_starts"}
    assert set(np.unique(rows["event"])) == {-1, 0, 1}
    spec = load_sensor("sphere8")
    model = make_sensor_model(spec, num_rays=16)
    poses = np.column_stack([rows[f"probe_{a}"] for a in ("x", "y", "z", "rx", "ry", "rz")])
    trajectory = make_trajectory(rows["time"], poses[:, :3], poses[:, 3:])
    material = make_prony(MATERIAL["long_term"], MATERIAL["moduli"], MATERIAL["taus"])
    variation = manifest["sensor_variation"]
    signal = make_barometer_signal(spec.part, spec.num_taxels, gains=variation["gains"], offsets=variation["offsets_Pa"], noise_rms=0.0)
    capacity = SimCapacity(tets=2048, others=2048, pairs=16384, polygons=4096, taxel_pairs=8192, taxel_pieces=16384)
    while True:  # the buffers the whole session needs (calc_simulation flags an overflow, never truncates silently)
        samples = jax.jit(lambda t, capacity=capacity: calc_simulation(model, material, parse_probe(manifest["probe"]), t, capacity, barometer=signal))(trajectory)
        overflow = np.asarray(samples.unit.did_overflow)
        if not overflow.any():
            break
        capacity = capacity.grown_to(np.asarray(samples.unit.needed)[overflow])
    force = np.asarray(samples.force_S)
    for k, name in enumerate(("fx", "fy", "fz")):
        np.testing.assert_allclose(rows[name], force[:, k], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rows["fn"], np.asarray(samples.normal_force), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rows["theta"], np.asarray(samples.theta), rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(rows["contact"], np.asarray(samples.contact).astype(np.int8))
    readings = np.column_stack([rows[name] for name in dataset.channels])
    assert np.max(np.abs(readings - np.asarray(samples.readings))) <= spec.part.lsb_pa  # quantised alike, to one LSB at a tie
    assert np.max(rows["fn"]) > 0.2


def test_residual_stress_carries_from_event_to_event():
    """The response at an event's hold equals its own response with a fresh skin plus
    the relaxing memory of the events before it (the Prony terms' hereditary integral
    of the earlier events alone): the session is one continuous timeline."""
    from hydrotact.sim import make_sensor_model
    from hydrotact.visco import calc_hereditary_integral, make_prony

    spec = load_sensor("sphere8")
    config = DatasetConfig(events=2, seed=4, probe=COARSE_SPHERE, num_rays=16, hold_range=(4.0, 4.0), gap_range=(0.3, 0.3), speed_range=(0.02, 0.02), force_range=(0.3, 0.5))
    model = make_sensor_model(spec, num_rays=16)
    from hydrotact.contact import parse_probe

    material = make_prony(5e5, [1e6], [3.0])  # a slow, strong term: the first hold's memory is large at the second
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), config, np.random.default_rng(0))
    presses = march_presses(PoseEngine(model, parse_probe(config.probe)), plan, config, float(material.instantaneous_modulus))
    assert presses.reached.all()
    np.testing.assert_allclose(presses.hold_forces, plan.target_forces, rtol=0.05)  # the hold depth reaches the target force
    # The march computes few poses past each target (the √F prediction): per event its
    # approach, the first sample at the target, at most one more, and the hold; and the far pose.
    assert len(presses.rows) <= sum(len(a) + 3 for a in presses.approach) + 1
    timeline = lay_out_timeline(plan, presses, config)
    columns = run_session(model, material, presses, timeline, config, None, None)
    unit_fz = presses.table["force_S"][timeline.pose, 2]
    times = columns["time"]
    second = timeline.event == 1
    at = np.flatnonzero(second & (timeline.phase == 2))[0]  # the second hold's first sample
    first_only = np.where(timeline.event == 0, unit_fz, 0.0)
    memory = np.asarray(calc_hereditary_integral(material, times, first_only))[at]
    fresh = np.asarray(calc_hereditary_integral(material, times[second], unit_fz[second]))[at - np.flatnonzero(second)[0]]
    assert memory * fresh < 0.0 and abs(memory) > 0.02 * abs(fresh)  # the relaxed skin still pulls back, by a few per cent
    np.testing.assert_allclose(columns["fz"][at], fresh + memory, rtol=1e-9)


def test_presses_at_the_board_stop_at_their_target_along_the_approach():
    """Where sphere8's skin meets the board the field's normal is no guide to the load:
    the march stops on the force along the approach (what a gantry controls), so the
    whole force stays near the target and the probe does not sink past its radius
    (stopping on the normal force instead, one of these two presses sank to the 6 mm
    limit with 2 N along the normal; in a 250-event dataset two presses so reached 20 and 30 N)."""
    from hydrotact.contact import parse_probe
    from hydrotact.sim import make_sensor_model

    spec = load_sensor("sphere8")
    config = DatasetConfig(events=250, probe=COARSE_SPHERE, num_rays=16, force_range=(4.0, 6.0))
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), config, np.random.default_rng(4))
    lowest = np.argsort(plan.points[:, 2])[:2]
    assert np.all(plan.points[lowest, 2] < 0.5e-3)  # at the board (z = 0)
    plan = dataclasses.replace(plan, **{field.name: getattr(plan, field.name)[lowest] for field in dataclasses.fields(plan)})
    modulus = 3e6
    presses = march_presses(PoseEngine(make_sensor_model(spec, num_rays=16), parse_probe(config.probe)), plan, config, modulus)
    assert presses.reached.all()
    np.testing.assert_allclose(presses.hold_forces, plan.target_forces, rtol=0.05)
    whole = modulus * np.linalg.norm(presses.table["force_S"][presses.hold], axis=1)
    assert np.all(whole < 1.2 * plan.target_forces), (whole, plan.target_forces)
    assert np.all(presses.hold_depths < 3e-3), presses.hold_depths


def test_the_papers_depth_regime_holds_at_the_drawn_depths():
    """With target depths (the barometric estimation paper's regime) the plan draws
    depths uniformly in their range and no forces, every press marches to the first
    sample at or past its depth and holds at the depth itself, the forces follow (rising
    with depth), and a depth past the event's limit holds at the limit, not reached;
    the force-target plan's draws are unchanged by the option."""
    from hydrotact.contact import parse_probe
    from hydrotact.sim import make_sensor_model

    spec = load_sensor("sphere8")
    skin = find_touchable_skin(spec, spec.make_mesh(check=False))
    wide = sample_events(skin, DatasetConfig(events=4000, target="depth", depth_range=(0.5e-3, 2.5e-3)), np.random.default_rng(1))
    assert np.all(np.isnan(wide.target_forces))
    assert stats.kstest((wide.target_depths - 0.5e-3) / 2e-3, "uniform").pvalue > 1e-3
    by_force = sample_events(skin, DatasetConfig(events=50), np.random.default_rng(2))
    again = sample_events(skin, DatasetConfig(events=50, depth_range=(1e-3, 2e-3)), np.random.default_rng(2))
    np.testing.assert_array_equal(by_force.target_forces, again.target_forces)
    assert np.all(np.isnan(by_force.target_depths))

    config = DatasetConfig(events=3, probe=COARSE_SPHERE, num_rays=16, target="depth", depth_range=(0.3e-3, 1.2e-3), speed_range=(0.02, 0.02), max_depth=1.0e-3)
    plan = sample_events(skin, config, np.random.default_rng(0))
    plan = dataclasses.replace(plan, target_depths=np.array([0.35e-3, 0.8e-3, 1.15e-3]))  # the last past max_depth
    presses = march_presses(PoseEngine(make_sensor_model(spec, num_rays=16), parse_probe(config.probe)), plan, config, 5e6)
    np.testing.assert_array_equal(presses.reached, [True, True, False])
    np.testing.assert_allclose(presses.hold_depths[:2], plan.target_depths[:2], rtol=0, atol=1e-15)
    step = 0.02 / config.rate_hz
    assert presses.hold_depths[2] <= config.max_depth and presses.hold_depths[2] > config.max_depth - step
    for event in range(3):
        depths = presses.depths[event]
        assert depths[-1] < presses.hold_depths[event] + 1e-15 and depths[-1] > presses.hold_depths[event] - step - 1e-15
        along = presses.table["force_S"][presses.approach[event]] @ plan.directions[event] * 5e6
        assert np.all(np.diff(along) >= 0.0) and 0.0 < along[-1] <= presses.hold_forces[event]  # the forces follow the depth


def test_slices_start_on_the_rung_their_predicted_needs_fit():
    """The engine starts a slice on the lowest rung of its ladder that holds what its
    poses are predicted to need: a start too low climbs to where they fit, one too high
    stays there, and either way the responses are those computed from the bottom
    rung (to round-off: a longer buffer can change a sum in its last bit). Every rung
    holds all of the probe's triangles."""
    from hydrotact.contact import parse_probe
    from hydrotact.datasets import _compute, compute_block
    from hydrotact.sim import make_sensor_model

    spec = load_sensor("sphere8")
    probe = parse_probe(COARSE_SPHERE)
    model = make_sensor_model(spec, num_rays=16)
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), DatasetConfig(events=8), np.random.default_rng(6))
    event, depth = np.repeat(np.arange(8), 8), np.tile(np.linspace(0.1e-3, 1.6e-3, 8), 8)
    rows = np.column_stack([plan.points[event] + depth[:, None] * plan.directions[event], plan.rotation_vectors[event]])
    ladder = _compute._ladder(probe)
    assert [rung.others for rung in ladder] == [len(probe.faces)] * len(ladder)
    used = []
    kernel = _compute._kernel

    def recording(capacity):
        used.append(ladder.index(capacity))
        return kernel(capacity)

    from unittest import mock

    with mock.patch.object(_compute, "_kernel", recording):
        bottom = compute_block(model, probe, rows)
        fits = int(_compute.calc_start_rungs(probe, bottom["needed"]).max())
        # From the bottom it climbs to the rung that fits (in more than one step when a
        # truncated contact under-counted what the taxel buffers need).
        assert fits > 0 and used[0] == 0 and used[-1] == fits and used == sorted(set(used))
        used.clear()
        exact = compute_block(model, probe, rows, needs=bottom["needed"])
        assert used == [fits]
        used.clear()
        high = compute_block(model, probe, rows, needs=np.tile(ladder[fits + 1].sizes, (len(rows), 1)))
        assert used == [fits + 1]
    for name in ("force_S", "area", "taxel_pressures", "contact_point_S"):
        for other in (exact, high):
            np.testing.assert_allclose(other[name], bottom[name], rtol=1e-12, atol=1e-15 * np.abs(bottom[name]).max(), err_msg=name)
    assert not bottom["did_overflow"].any() and not high["did_overflow"].any()


# --- determinism, resumption, scale-out ---------------------------------------------


def _command(output, material_file, *extra):
    return [sys.executable, "-m", "hydrotact.cli", "generate", *ARGS, "--material", str(material_file), "-o", str(output), "--no-plots", "--json", *extra]


def test_a_run_killed_and_resumed_on_four_devices_gives_the_same_bytes(reference, material_file, tmp_path):
    """A run on one device killed (SIGKILL) after its first batch of poses, then run
    again on four host devices (XLA_FLAGS): the same bytes as the uninterrupted
    one-device run. Both claims in one run (each generate costs minutes here): the
    resumed run reuses the first batch and computes every later one on four devices."""
    output = tmp_path / "killed"
    env = os.environ | {"HYDROTACT_CACHE_DIR": os.environ.get("HYDROTACT_CACHE_DIR", str(tmp_path / "cache"))}
    process = subprocess.Popen(_command(output, material_file), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 600
    while not (output / ".partial" / "batch-00000.npz").exists():
        assert process.poll() is None, "the run ended before its first batch was saved"
        assert time.monotonic() < deadline
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert not (output / "manifest.json").exists()
    saved = sorted(path.name for path in (output / ".partial").glob("batch-*.npz"))
    # Four devices on top of the compiler's own flags (`make test` compiles at -O0): the reference ran with them.
    four = env | {"XLA_FLAGS": f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=4".strip()}
    finished = subprocess.run(_command(output, material_file), env=four, capture_output=True, text=True, timeout=900)
    assert finished.returncode == 0, finished.stderr
    assert json.loads(finished.stdout)["rounds"] > len(saved)  # batches were left for the four devices (a smoke round is one batch)
    assert _shards(output) == _shards(reference)
    assert not (output / ".partial").exists()
    again = subprocess.run(_command(output, material_file), env=env, capture_output=True, text=True, timeout=900)
    assert again.returncode == 0 and json.loads(again.stdout)["status"] == "complete"


def test_two_ray_workers_give_the_same_bytes(reference, material_file, tmp_path):
    """A local Ray cluster of two worker CPUs, started here; the pose batches go to it
    as tasks."""
    pytest.importorskip("ray")
    import tempfile

    ray_dir = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp"))  # Ray's socket paths must stay under 108 bytes
    # Ray runs its workers at niceness 15: beside the suite's other test process they would
    # starve (a 5-event run took over 15 min so); this cluster's workers run at 0.
    env = os.environ | {"RAY_TMPDIR": str(ray_dir), "RAY_worker_niceness": "0"}
    ray = str(Path(sys.executable).parent / "ray")  # the environment's own Ray command
    started = subprocess.run([ray, "start", "--head", "--num-cpus=2", "--port=0", "--include-dashboard=false", f"--temp-dir={ray_dir}", "--disable-usage-stats"],
                             env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert started.returncode == 0, started.stderr
    try:
        output = tmp_path / "ray-output"
        finished = subprocess.run(_command(output, material_file, "--ray", "auto"), env=env, capture_output=True, text=True, timeout=1500)
        assert finished.returncode == 0, finished.stderr
        assert _shards(output) == _shards(reference)
    finally:
        subprocess.run([ray, "stop", "--force"], env=env, capture_output=True, timeout=120)
        import shutil

        shutil.rmtree(ray_dir, ignore_errors=True)


# --- refusals -----------------------------------------------------------------------


def test_a_manifest_whose_split_or_shards_do_not_match_its_rows_is_refused(reference, tmp_path):
    """A split pointing past the dataset's rows (an edited manifest) or shards that do
    not add up to its rows: one error naming the field, not a training on nothing."""
    for edit, words in (
        (lambda m: m["split"]["train"].__setitem__(0, [0, m["num_rows"] + 500]), "split.train[0]"),
        (lambda m: m.__setitem__("num_rows", m["num_rows"] + 1), "num_rows"),
    ):
        folder = tmp_path / words.replace("[", "").replace("]", "").replace(".", "_")
        folder.mkdir()
        for entry in reference.iterdir():
            if entry.is_file():
                (folder / entry.name).write_bytes(entry.read_bytes())
        manifest = json.loads((folder / "manifest.json").read_text())
        edit(manifest)
        (folder / "manifest.json").write_text(json.dumps(manifest))
        with pytest.raises(HydrotactError, match=re.escape(words)):
            load_dataset(folder)


def test_foreign_corrupt_and_other_folders_are_refused_untouched(reference, material_file, tmp_path, capsys):
    from hydrotact.cli import main

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "manifest.json").write_text("{not json")
    (corrupt / "shard-00000.parquet").write_bytes(b"PAR1")
    other = tmp_path / "other"
    other.mkdir()
    for entry in reference.iterdir():
        (other / entry.name).write_bytes(entry.read_bytes())
    partial = tmp_path / "partial"
    (partial / ".partial").mkdir(parents=True)
    (partial / ".partial" / "state.json").write_text(json.dumps({"request_digest": "0" * 64}))
    for folder, words in ((foreign, "notes.txt"), (corrupt, "manifest"), (other, "another dataset"), (partial, "unfinished run of another dataset")):
        before = {path: path.read_bytes() for path in folder.rglob("*") if path.is_file()}
        extra = ["--seed", "4"] if folder is other else []
        assert main(["generate", *ARGS, "--material", str(material_file), "-o", str(folder), *extra]) == 2
        error = capsys.readouterr().err
        assert error.startswith("hydrotact: error: ") and words in error and error.count("\n") == 1
        assert {path: path.read_bytes() for path in folder.rglob("*") if path.is_file()} == before
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    for entry in reference.iterdir():
        (damaged / entry.name).write_bytes(entry.read_bytes())
    shard = damaged / "shard-00001.parquet"
    shard.write_bytes(shard.read_bytes()[:-9] + b"123456789")
    with pytest.raises(HydrotactError, match="SHA-256"):
        load_dataset(damaged).table()


def test_randomised_material_is_drawn_from_the_covariance_and_recorded(material_file):
    from hydrotact.data import read_material
    from hydrotact.datasets import draw_material

    document = read_material(material_file)
    draws = [draw_material(document, np.random.default_rng(seed), "m.json")[0] for seed in range(400)]
    logs = np.log([[d["long_term_modulus_Pa"], d["moduli_Pa"][0], d["taus_s"][0]] for d in draws])
    np.testing.assert_allclose(logs.mean(axis=0), np.log([MATERIAL["long_term"], MATERIAL["moduli"][0], MATERIAL["taus"][0]]), atol=0.04)
    np.testing.assert_allclose(logs.std(axis=0), np.sqrt([0.01, 0.04, 0.04]), rtol=0.12)
    no_spread = {key: value for key, value in document.items() if key != "covariance"}
    with pytest.raises(HydrotactError, match="covariance or standard deviations"):
        draw_material(no_spread, np.random.default_rng(0), "plain.json")


def test_batches_read_back_from_a_killed_runs_checkpoint_are_told_apart(tmp_path):
    """A resumed run's progress counts the batches it reads back apart from those it
    computes (its rate was the read-back's, its bar silent about resuming)."""
    from hydrotact.datasets._session import _Rounds

    computed = []

    class Engine:
        def compute(self, rows, needs):
            computed.append(len(rows))
            return {"value": rows.astype(np.float64).sum(axis=1)}

    seen = []
    rows, needs = np.arange(12).reshape(6, 2), np.zeros((6, 6))
    _Rounds(Engine(), tmp_path, lambda n, restored: seen.append((n, restored))).add(rows, needs)
    _Rounds(Engine(), tmp_path, lambda n, restored: seen.append((n, restored))).add(rows, needs)
    assert seen == [(6, False), (6, True)] and computed == [6]
