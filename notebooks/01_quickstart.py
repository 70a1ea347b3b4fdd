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
# # hydrotact quickstart: from a mesh to a simulated barometer log
#
# The whole forward model on the flat 5 x 5 array of the hydroelastic tactile paper:
#
# 1. the **mesh** of the silicone pad (tets, with the bottom bonded to the PCB),
# 2. its **strain field** (Laplace: 0 on the skin, 1 on the PCB), p = E e,
# 3. the **contact surface** of a 2 mm cylinder probe pressed into it,
# 4. what each of the 25 **taxels** (barometers) reads of it, by ray casting,
# 5. a short **simulated log** of a probe sliding across the pad.
#
# Set `HYDROTACT_SMOKE=1` to run it at the small size the test suite uses.

# %%
import os

import jax

jax.config.update("jax_enable_x64", True)  # float64 for reference accuracy

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, display

from hydrotact.contact import compute_contact_surface, make_cylinder_probe, make_pose
from hydrotact.sensors import load_sensor
from hydrotact.sim import make_sensor_model, make_trajectory, simulate
from hydrotact.taxel import sample_taxels
from hydrotact.visco import make_prony

SMOKE = os.environ.get("HYDROTACT_SMOKE") == "1"
OUT = os.environ.get("HYDROTACT_NOTEBOOK_OUT", "quickstart_out")
os.makedirs(OUT, exist_ok=True)

# %% [markdown]
# ## 1. The sensor and its mesh
#
# A sensor spec (JSON, validated against `data_schemas/sensor.schema.json`) says where
# the elastomer is and where its barometers sit. `pad5x5` is built in.

# %%
spec = load_sensor("pad5x5")
print(spec.description)
mesh = spec.make_mesh()
print(f"{mesh.num_tets} tets, {mesh.num_vertices} vertices; {spec.num_taxels} taxels, part {spec.part.name}")

# %%
from hydrotact.viz import render_field, render_mesh

render_mesh(mesh, f"{OUT}/pad_mesh.png", title="pad5x5")
display(Image(f"{OUT}/pad_mesh.png", width=480))

# %% [markdown]
# ## 2. The strain field
#
# `make_sensor_model` solves the Laplace strain field once (unit modulus) and lays out
# the taxels. Forces and pressures scale with the material's modulus E.

# %%
model = make_sensor_model(spec, num_rays=16 if SMOKE else 64)
modulus = 1e6  # Pa
render_field(mesh, modulus * np.asarray(model.field.strain), f"{OUT}/pad_field.png", label="pressure [Pa]", title=f"E = {modulus:g} Pa")
display(Image(f"{OUT}/pad_field.png", width=480))

# %% [markdown]
# ## 3. A contact surface
#
# The 2 mm probe pressed 0.45 mm into the skin, a little off the centre cell.

# %%
import equinox as eqx
import jax.numpy as jnp

from hydrotact.viz import render_contact

probe = make_cylinder_probe(2e-3)
X_SR = make_pose([0.6e-3, 0.2e-3, 4e-3 - 0.45e-3])
field = eqx.tree_at(lambda f: f.modulus, model.field, jnp.asarray(modulus))
surface, capacity = compute_contact_surface(field, probe, X_SR, clusters=model.clusters)
force, torque = surface.calc_wrench()
print(f"{int(surface.num_polygons)} polygons, area {float(surface.total_area) * 1e6:.3f} mm^2, force on the sensor {np.asarray(force)} N")
render_contact(mesh, surface, f"{OUT}/pad_contact.png", probe=probe, X_SP=X_SR, title="2 mm probe, 0.45 mm deep")
display(Image(f"{OUT}/pad_contact.png", width=480))

# %% [markdown]
# ## 4. What the taxels read
#
# Each barometer looks up through a disk of radius 1.1 mm; its value is the weighted
# mean pressure of its rays' first hits, w = (r - d)^2, misses reading 0.

# %%
readings, _ = sample_taxels(model.layout, surface, model.num_rays)
grid = np.asarray(readings.pressures).reshape(5, 5) / 1e3
figure, axis = plt.subplots(figsize=(4.2, 3.6))
image = axis.imshow(grid, origin="lower", extent=[-5.5, 5.5, -5.5, 5.5], cmap="viridis")
axis.set_xlabel("x [mm]")
axis.set_ylabel("y [mm]")
figure.colorbar(image, label="taxel pressure [kPa]")
axis.set_title("taxel readings")
plt.show()

# %% [markdown]
# ## 5. A simulated log
#
# The probe slides along x at constant depth. `simulate` returns the taxel pressures,
# the wrench on the sensor, the normal force and the contact flag at every sample.

# %%
num_samples = 6 if SMOKE else 60
times = np.arange(num_samples) * 0.01
x = np.linspace(-3e-3, 3e-3, num_samples)
trajectory = make_trajectory(times, np.column_stack([x, np.zeros_like(x), np.full_like(x, 4e-3 - 0.45e-3)]))
samples = simulate(model, make_prony(modulus), probe, trajectory)  # an elastic material: no Prony terms

figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
for k in (11, 12, 13):
    top.plot(1e3 * x, samples.taxel_pressures[:, k] / 1e3, label=spec.taxel_names[k])
top.set_ylabel("taxel pressure [kPa]")
top.legend()
bottom.plot(1e3 * x, samples.normal_force, "k")
bottom.set_ylabel("normal force [N]")
bottom.set_xlabel("probe x [mm]")
plt.show()
assert np.all(samples.normal_force > 0.1) and np.all(samples.contact)
