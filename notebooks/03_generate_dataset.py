# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Generate a synthetic training dataset
#
# With a material fitted to your logs (notebook 02), the simulator can stand in for the
# gantry: it presses a probe into the sensor over and over, as the barometric
# estimation paper's data collection did — about **2500 contact events over three
# hours at 100 Hz**, at random places on the skin, normal forces 0-8 N with **low forces
# over-sampled**, each held 0.5-5 s — and writes what the barometers read with the
# labels an estimator learns: Fx, Fy, Fz, the normal force, the contact angles θ and φ,
# the contact flag.
#
# 1. **The regime**: `DatasetConfig`, and where the events land (uniform by *area* over
#    the skin, not by angle).
# 2. **Generate**: `hydrotact generate` in Python; sharded Parquet and a manifest;
#    deterministic for a seed; an interrupted run resumes.
# 3. **Look at it**: coverage, label histograms, the channels' swing against the
#    published statistics of real sensors, example events.
# 4. **Read it back for training**: `load_dataset`, the train/test split, windows.
#
# `HYDROTACT_SMOKE=1` runs it at the test suite's size (a handful of short events).

# %%
import os
from pathlib import Path

import jax
import numpy as np
from IPython.display import Image, display

jax.config.update("jax_enable_x64", True)
SMOKE = os.environ.get("HYDROTACT_SMOKE") == "1"
OUT = Path(os.environ.get("HYDROTACT_NOTEBOOK_OUT", "generate_dataset_out"))
OUT.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## 1. The regime
#
# Every number of the paper's regime is a field of `DatasetConfig`; our choices where
# the paper is silent (a 3 mm sphere, tilts up to 30° from the skin normal, approach
# speeds 4-20 mm/s, gaps 0.5-2 s) are documented there. The material: here a
# viscoelastic silicone (E(0) 10 MPa, the generator's default) written as a material
# document, as `hydrotact fit` writes one.

# %%
from hydrotact.data import make_material_document, write_material
from hydrotact.datasets import DatasetConfig, find_touchable_skin, sample_events
from hydrotact.sensors import load_sensor

material_path = write_material(
    OUT / "material.json",
    make_material_document(6e6, [2.5e6, 1.5e6], [0.8, 12.0], covariance=np.diag([0.01, 0.04, 0.04, 0.02, 0.02]), name="silicone (example)"),
)
if SMOKE:
    config = DatasetConfig(events=4, seed=0, probe="sphere:r=3mm,subdivisions=1", num_rays=16, hold_range=(0.3, 0.6), gap_range=(0.2, 0.4), speed_range=(0.01, 0.02), force_range=(0.2, 2.0))
else:
    config = DatasetConfig(events=300, seed=0)
print(config)

# %% [markdown]
# Contact points are drawn uniformly by area over the *touchable* skin: the free faces
# within the sensor's contact-angle ranges. On sphere8 that is the paper's θ ∈ ±45°,
# φ ∈ [−135°, 45°]; uniform in (θ, φ) instead would crowd the patches near θ = ±45°.

# %%
spec = load_sensor("sphere8")
skin = find_touchable_skin(spec, spec.make_mesh(check=False))
plan = sample_events(skin, DatasetConfig(events=2000), np.random.default_rng(0))
print(f"touchable skin: {len(skin.areas)} triangles, {skin.area * 1e6:.0f} mm²")
print(f"target forces: median {np.median(plan.target_forces):.2f} N, {np.mean(plan.target_forces < 1.0):.0%} below 1 N (log-uniform 0.05-8 N)")

# %% [markdown]
# ## 2. Generate
#
# `generate_dataset` is what `hydrotact generate --sensor sphere8 --material material.json -o DIR`
# runs. The expensive part — the contact and the barometers' unit responses at every
# distinct probe pose — runs on every local JAX device (or on a Ray cluster with
# `--ray auto`); then the whole session goes through the viscoelastic model at once, so
# the skin's memory of one press is still there at the next.

# %%
from hydrotact.datasets import generate_dataset, load_dataset

folder = OUT / "sphere8_dataset"
manifest = generate_dataset("sphere8", folder, material=material_path, config=config)
print(f"{manifest['status']}: {manifest['num_events']} events, {manifest['num_rows']} rows ({manifest['duration_s'] / 60:.1f} min at {manifest['rate_hz']:g} Hz), "
      f"{manifest['num_distinct_poses']} distinct poses, {len(manifest['shards'])} shards, {manifest['elapsed_s']:.0f} s")
print("channel std (kPa):", np.round(1e-3 * np.asarray(manifest["statistics"]["channel_std_Pa"]), 2), "- published real sensors: 3-9 kPa")

# %% [markdown]
# Run it again and nothing is recomputed: the folder already holds this dataset (the
# manifest's `request_digest` is that of every input). Kill a long run and start it
# again: it picks up the unit responses it had saved.

# %%
print(generate_dataset("sphere8", folder, material=material_path, config=config)["status"])

# %% [markdown]
# ## 3. Look at it

# %%
from hydrotact.viz import plot_dataset

dataset = load_dataset(folder)
for path in plot_dataset(dataset, OUT):
    display(Image(filename=str(path)))

# %% [markdown]
# ## 4. Read it back for training
#
# The split holds out contiguous blocks of events (70/30 by default), so a test window
# never shares a press with a training one. `windows` gives fixed-length windows that
# never cross a block's edge: what the estimator of the next notebook trains on.

# %%
train, test = dataset.arrays("train"), dataset.arrays("test")
print(f"train {len(train['time'])} rows in {len(train['block_starts'])} blocks, test {len(test['time'])} rows")
windows = list(dataset.windows("train", length=64, stride=32, columns=[*dataset.channels, "fn", "contact"]))
print(f"{len(windows)} training windows of 64 samples; inputs {dataset.channels}; labels {dataset.labels[:7]}")
