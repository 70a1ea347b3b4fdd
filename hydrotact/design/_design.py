"""Design a sensor's barometer layout by gradient (host driver).

`design_layout` draws the contacts of a dataset regime over the sensor's touchable
skin, linearises them once, then from several feasible starts (the sensor's own layout
when the count matches, and random packings) climbs the objective of
:mod:`._objective` with Adam (optax), projecting onto the feasible layouts of
:mod:`._feasible` after every step. The best layout is written into a copy of the
sensor spec. Every layout it reports is also scored on a second, independent set of
contacts (held out), so a layout that only fits the design's contacts shows.
"""

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._files import atomic_path
from ..taxel import make_taxel_layout
from ._config import OBJECTIVE_DESCRIPTIONS, DesignConfig, LayoutDesign, LayoutScore
from ._elastic import ElasticDesigner, calc_readout_information, climb_elastic
from ._feasible import Placement, make_feasible_region
from ._objective import DesignObjective, NoiseModel, calc_neighbour_targets, calc_prior_precision
from ._search import POSITION_UNIT, START_TAXEL_CAPACITY, _climb, _make_scorer, _score_information, _score_layout, _size_units  # _climb looked up here: the tests replace it


def draw_design_contacts(spec, model, regime, modulus: float, count: int, rng: np.random.Generator):
    """`count` contacts of the regime: skin points uniform by area over the touchable
    skin, pressed along the inward normal to target forces (or depths) drawn like a
    dataset's, no deeper than the regime allows (:func:`linearise_contacts`)."""
    from ..contact import parse_probe
    from ..datasets import calc_approach_thickness, draw_hold_targets, find_touchable_skin, pressing_rotation_vectors, sample_skin_points
    from ._contacts import linearise_contacts

    skin = find_touchable_skin(spec, spec.make_mesh(check=False))
    points, normals, _ = sample_skin_points(skin, count, rng)
    forces, depths = draw_hold_targets(regime, count, rng)
    depths = depths if regime.target == "depth" else None
    deepest = np.minimum(regime.max_depth, regime.max_depth_fraction * calc_approach_thickness(skin, points, -normals))
    contacts = linearise_contacts(model, parse_probe(regime.probe), modulus, points, normals, forces, deepest, pressing_rotation_vectors(-normals), target_depths=depths)
    return contacts, skin.area


def design_layout(
    sensor, num_barometers: int | None = None, *, config: DesignConfig | None = None, regime=None, material=None, modulus=None,
    compare: dict | None = None, checkpoint=None, progress: bool = False,
) -> LayoutDesign:
    """Design the layout of `num_barometers` barometers (default: as many as the
    sensor has) for a sensor (a SensorSpec, a built-in name or a spec file), its
    elastomer and barometer part (host).

    **Arguments:**

    - `config`: how (:class:`DesignConfig`).
    - `regime`: the contacts' regime, a :class:`hydrotact.datasets.DatasetConfig`
      (probe, force distribution and range, deepest press); the paper's by default.
    - `material`, `modulus`: the elastomer, a material document or file, or an elastic
      modulus (Pa; default 10 MPa, the dataset generator's); its E(0) is used.
    - `checkpoint`: a folder where each finished start is kept (`start-K.npz`, with
      the request's digest in `state.json`): a run killed and started again with the
      same request resumes after its last finished start (None: nothing kept). The
      caller removes it after success.
    - `progress`: a progress bar over the steps.

    **Returns:** a :class:`LayoutDesign`. An infeasible request (more barometers than
    fit `spacing` apart) is refused with a HydrotactError before any work.
    """
    from tqdm.auto import tqdm

    from .._defaults import DEFAULT_DATASET_MODULUS
    from ..datasets import DatasetConfig
    from ..sensors import SensorSpec, load_sensor
    from ..sim import make_sensor_model

    started = time.perf_counter()
    config = config or DesignConfig()
    regime = regime or DatasetConfig()
    spec = sensor if isinstance(sensor, SensorSpec) else load_sensor(sensor)
    elastic = bool(spec.is_elastic.any())
    if elastic and not spec.is_elastic.all():
        # One readout per design: elastic barometers' linearised fields, or ray-cast taxels.
        names = ", ".join(name for name, is_elastic in zip(spec.taxel_names, spec.is_elastic, strict=True) if is_elastic)
        raise HydrotactError(
            f"{spec.source}: design moves either elastic barometers or ray-cast taxels (disk, cone), and only barometers {names} are elastic; "
            "make every barometer elastic, or none"
        )
    if elastic and config.field_sizes:
        raise HydrotactError(f"{spec.source}: --field-sizes designs ray-cast fields' sizes; an elastic barometer's port radius is its part's")
    count = spec.num_taxels if num_barometers is None else num_barometers
    if not isinstance(count, int | np.integer) or isinstance(count, bool) or count < 1:
        raise HydrotactError(f"--barometers: must be a whole number of at least 1, got {count!r}")
    objective = DesignObjective.parse(config.objective, "objective")
    mesh = spec.make_mesh(check=False)
    placement = config.placement or (Placement.BOARD if np.allclose(spec.taxel_positions_S[:, 2], np.min(mesh.vertices[:, 2]), atol=1e-9) else Placement.INSIDE)
    region = make_feasible_region(mesh, placement, config.margin, config.spacing, config.max_tilt_deg, config.max_height)
    rng = np.random.default_rng(config.seed)
    known = _own_layout(region, spec)  # feasible: a certificate that as many ports fit
    starts = [region.random_layout(count, rng, known) for _ in range(config.restarts)]  # refuses an impossible count first
    if not starts:  # no random start asked for: an impossible count, spacing or margin is still refused before any work
        region.random_layout(count, np.random.default_rng(config.seed), known)
        if count != spec.num_taxels:
            raise HydrotactError(
                f"--restarts 0 with --barometers {count}: the only start without random ones is the sensor's own layout, of {spec.num_taxels} barometers; "
                f"ask for {spec.num_taxels} barometers, or for random starts (--restarts 1 or more)"
            )
    compare = {name: (np.asarray(p, dtype=np.float64), np.asarray(a, dtype=np.float64)) for name, (p, a) in (compare or {}).items()}
    for name, (positions, axes) in compare.items():
        if positions.shape != (count, 3) or axes.shape != (count, 3):
            raise HydrotactError(f"compare[{name!r}]: needs ({count}, 3) positions and axes, got {positions.shape} and {axes.shape}")
        problems = region.violations(positions, axes)
        if problems:
            raise HydrotactError(f"compare[{name!r}]: the layout breaks the design's constraints: {problems[0]}")
    modulus_pa = _modulus(material, modulus, DEFAULT_DATASET_MODULUS)

    if checkpoint is not None:
        checkpoint = _start_checkpoint(checkpoint, {"sensor": spec.to_json(), "count": int(count), "config": config.to_json(), "regime": regime.to_json(), "modulus": modulus_pa})
    model = make_sensor_model(spec, num_rays=config.num_rays)
    # One draw of twice the contacts (one compilation), halved: the design's and the held-out.
    both, skin_area = draw_design_contacts(spec, model, regime, modulus_pa, 2 * config.contacts, rng)
    contacts = jax.tree_util.tree_map(lambda a: a[: config.contacts] if np.ndim(a) else a, both)
    held_out = jax.tree_util.tree_map(lambda a: a[config.contacts :] if np.ndim(a) else a, both)
    targets = calc_neighbour_targets(both.points_S, spec.contact_center_S)  # the learned objective's (and the reported error's)
    targets, held_out_targets = targets[: config.contacts], targets[config.contacts :]
    noise = make_noise_model(spec.part, config)
    prior = calc_prior_precision(skin_area, both.forces)
    kind = spec.taxel_field_kinds[0]
    size = float(np.median(spec.taxel_field_sizes))
    kinds = spec.taxel_field_kinds if count == spec.num_taxels else (kind,) * count
    sizes = spec.taxel_field_sizes if count == spec.num_taxels else np.full(count, size)
    elastic_readings = spec.taxel_elastic_readings if count == spec.num_taxels else (spec.taxel_elastic_readings[0],) * count
    # An elastic design's template only carries the sizes' units (mm, as a disk's).
    template = make_taxel_layout(np.zeros((count, 3)), np.tile([0.0, 0.0, 1.0], (count, 1)), ("disk",) * count if elastic else kinds, sizes)
    designer = ElasticDesigner(mesh, spec.poisson_ratio, sizes, elastic_readings, source=spec.name, progress=progress) if elastic else None
    rms = lambda errors: float(np.sqrt(np.mean(errors**2)))

    def exact_score(readout, positions, axes, which=None):
        chosen, chosen_targets = (contacts, targets) if which is None else which
        information = calc_readout_information(readout, jnp.asarray(positions), jnp.asarray(axes / np.linalg.norm(axes, axis=1, keepdims=True)), chosen, noise)
        return _score_information(information, chosen_targets, noise, prior, objective, config.balance)

    def score(positions, axes, sizes_, capacity):
        if designer is not None:
            value = exact_score(designer.readout(positions, axes, contacts, derivatives=False), positions, axes)[0]
            held, bounds, neighbour = exact_score(designer.readout(positions, axes, held_out, derivatives=False), positions, axes, (held_out, held_out_targets))
            return LayoutScore(float(value), float(held), bounds, rms(bounds), neighbour, rms(neighbour)), capacity
        layout = make_taxel_layout(positions, axes, kinds, sizes_)
        value, _, _, capacity = _score_layout(layout, contacts, targets, noise, prior, objective, config.num_rays, capacity, config.balance)
        held, bounds, neighbour, capacity = _score_layout(layout, held_out, held_out_targets, noise, prior, objective, config.num_rays, capacity, config.balance)
        return LayoutScore(value, held, bounds, rms(bounds), neighbour, rms(neighbour)), capacity

    capacity = START_TAXEL_CAPACITY
    named = [(f"random {i}", positions, axes) for i, (positions, axes) in enumerate(starts)]
    builtin = None
    if count == spec.num_taxels:
        builtin, capacity = score(spec.taxel_positions_S, spec.taxel_axes_S, sizes, capacity)
        own = (known if known is not None else region.project_positions(spec.taxel_positions_S)), region.project_axes(spec.taxel_axes_S)
        named.insert(0, ("sensor's own", *own))
    random_scores = []
    for _, positions, axes in named[1 if builtin is not None else 0 :]:
        scored, capacity = score(positions, axes, sizes, capacity)
        random_scores.append(scored)
    compared = {}
    for name, (positions, axes) in compare.items():
        compared[name], capacity = score(positions, axes, sizes, capacity)

    scorer = _make_scorer(contacts, targets, noise, prior, objective, config.num_rays, config.balance)
    # The learned objective needs every contact each step (each is the others' neighbour).
    climbing = dataclasses.replace(config, batch=config.contacts) if objective == DesignObjective.K else config

    def pool_score(params):
        nonlocal capacity
        layout = make_taxel_layout(np.asarray(params[0]) * POSITION_UNIT, np.asarray(params[1]), kinds, np.asarray(params[2]) * np.asarray(_size_units(template)))
        value, _, _, capacity = _score_layout(layout, contacts, targets, noise, prior, objective, config.num_rays, capacity, config.balance)
        return value

    results, histories = [], []
    with tqdm(total=len(named) * (config.steps + 1), unit="step", desc=f"designing {count} barometers for {spec.name}", disable=not progress) as bar:
        for name, positions, axes in named:
            bar.set_postfix_str(f"start: {name}", refresh=True)

            def on_step(value, bar=bar):
                bar.update(1)
                if value is not None:
                    bar.set_postfix_str(f"score {value:.5g}", refresh=False)

            before = bar.n
            kept = None if checkpoint is None else checkpoint / f"start-{len(results):02d}.npz"
            if kept is not None and kept.is_file():
                with np.load(kept) as saved:
                    best_positions, best_axes, best_sizes, history = (saved[k] for k in ("positions", "axes", "sizes", "history"))
            else:
                start_rng = np.random.default_rng([config.seed, len(results)])  # the same minibatches whether resumed or not
                if designer is not None:
                    best_positions, best_axes, best_sizes, history, capacity = climb_elastic(
                        designer, region, contacts, targets, noise, prior, objective, template, positions, axes, sizes, climbing, capacity, start_rng, on_step,
                        lambda readout, p, a: float(exact_score(readout, p, a)[0]),
                    )
                else:
                    best_positions, best_axes, best_sizes, history, capacity = _climb(
                        region, scorer, pool_score, template, positions, axes, sizes, climbing, capacity, start_rng, on_step
                    )
                if kept is not None:
                    with atomic_path(kept, suffix=".npz") as tmp:
                        np.savez(tmp, positions=best_positions, axes=best_axes, sizes=best_sizes, history=history)
            results.append((float(history[:, 1].max()), best_positions, best_axes, best_sizes))
            histories.append(history)
            bar.update(max(0, config.steps + 1 - (bar.n - before)))
    best = max(range(len(results)), key=lambda i: results[i][0])
    _, positions, axes, sizes_best = results[best]
    problems = region.violations(positions, axes)
    if problems:
        raise HydrotactError(f"the designed layout breaks its constraints: {problems[0]}")
    designed, capacity = score(positions, axes, sizes_best, capacity)
    designed_spec = _with_layout(spec, positions, axes, kinds, sizes_best, config, objective, elastic_readings)
    return LayoutDesign(
        spec=designed_spec, start_spec=spec, config=config, regime=regime, designed=designed, builtin=builtin, random=random_scores,
        histories=histories, start_names=[name for name, _, _ in named], start_layouts=[(positions, axes) for _, positions, axes in named],
        compared=compared, held_out_points_S=np.asarray(held_out.points_S),
        elapsed_s=time.perf_counter() - started,
    )


def make_noise_model(part, config: "DesignConfig | None" = None) -> NoiseModel:
    """The noise a design measures readings against: the barometer `part`'s white
    noise (or `config.noise_rms`) and quantisation, with `config`'s floor and relative
    part (default: :class:`DesignConfig`'s); its limit the part's range above ambient."""
    config = config or DesignConfig()
    return NoiseModel(
        noise_rms=jnp.asarray(float(part.noise_rms_pa if config.noise_rms is None else config.noise_rms)),
        lsb=jnp.asarray(float(part.lsb_pa)),
        floor=jnp.asarray(float(config.noise_floor)),
        relative_noise=jnp.asarray(float(config.relative_noise)),
        limit=jnp.asarray(float(part.range_pa[1] - part.ambient_pa)),
    )


def _own_layout(region, spec) -> "np.ndarray | None":
    """The sensor's own ports moved onto the design's feasible set, or None where
    they cannot all be placed there (the constraints then decide alone)."""
    try:
        positions = region.project_positions(spec.taxel_positions_S)
    except HydrotactError:
        return None
    return None if region.violations(positions, np.tile([0.0, 0.0, 1.0], (len(positions), 1))) else positions


def _start_checkpoint(folder, request: dict):
    """The checkpoint folder for `request`: made if absent; a folder of another request
    (its `state.json` digest differs) has its kept starts removed first."""
    import json
    from pathlib import Path

    from .._files import digest, write_text_atomic

    folder = Path(folder)
    key = digest(json.dumps(request, sort_keys=True))
    state = folder / "state.json"
    try:
        same = json.loads(state.read_text())["request_digest"] == key
    except (OSError, ValueError, KeyError, TypeError):
        same = False
    if not same:
        for kept in folder.glob("start-*.npz"):
            kept.unlink()
        write_text_atomic(state, json.dumps({"request_digest": key, "request": request}, indent=2) + "\n")
    return folder


def _modulus(material, modulus, default: float) -> float:
    if material is not None and modulus is not None:
        raise HydrotactError("give a material or a modulus, not both")
    if material is None:
        value = float(default if modulus is None else modulus)
        if not np.isfinite(value) or value <= 0.0:
            raise HydrotactError(f"--modulus: must be a positive pressure in Pa, got {value!r}")
        return value
    from ..data import material_prony, read_material

    document = material if isinstance(material, dict) else read_material(material)
    return float(material_prony(document, source=str(material) if not isinstance(material, dict) else "material document").instantaneous_modulus)


def _with_layout(spec, positions, axes, kinds, sizes, config: DesignConfig, objective, readings=None):
    """A copy of `spec` with the designed layout (channels b0..), its description
    saying how it was designed, checked like any spec read from a file."""
    from ..sensors import load_sensor

    count = len(positions)
    names = spec.taxel_names if count == spec.num_taxels else tuple(f"b{i}" for i in range(count))
    how = OBJECTIVE_DESCRIPTIONS[objective]
    risers = "" if config.max_height is None else f", at most {config.max_height * 1e3:g} mm above the board"
    description = (
        f"{spec.description} Layout designed by hydrotact design: {count} barometers, {how}, "
        f"placement {config.placement or 'as the sensor'}{risers}, spacing {config.spacing * 1e3:g} mm, margin {config.margin * 1e3:g} mm."
    )
    designed = dataclasses.replace(
        spec, name=f"{spec.name}_designed", description=description, taxel_names=tuple(names), taxel_positions_S=np.asarray(positions), taxel_axes_S=np.asarray(axes),
        taxel_field_kinds=tuple(kinds), taxel_field_sizes=np.asarray(sizes, dtype=np.float64),
        taxel_elastic_readings=tuple(readings) if readings is not None else ("pressure",) * count,
    )
    return load_sensor(designed.to_json(), source=f"the layout designed for {spec.name}")
