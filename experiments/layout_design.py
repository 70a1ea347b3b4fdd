"""A designed barometer layout against the built-in, a regular and a random one, proven
by retraining: the same binned GRU trained on a dataset made with each layout.

1. **Design** (`hydrotact.design.design_layout`): sphere8's eight barometers placed
   and pointed by gradient, from the sensor's own layout and random feasible starts,
   on a pool of contacts of the dataset regime; the baselines are scored on the
   design's held-out contacts too (score, the RMS Cramér–Rao bound on the
   localisation error, and the RMS leave-one-out error of a nearest-neighbour
   estimator). The design's contacts press a coarser mesh of the same 3 mm sphere
   (`--design-probe`; see DESIGN_PROBE). Three designs:
   - `risers`: the **learned** objective (`k`: the leave-one-out localisation error
     of a nearest-neighbour estimator learned from the pool's readings, 384 contacts),
     on risers as high as the built-in's highest (sphere8's barometers stand 1 and
     2 mm above its board): the same kind of sensor as the built-in, the main
     comparison;
   - `risers-d`: the D-optimal objective (the mean log det of the Fisher information
     of the contact point and force, 96 contacts) on the same risers;
   - `inside`: D-optimal anywhere in the elastomer (1 mm from its boundary),
     barometers cast in up to just under the skin.
   The D-optimal designs came first; retrained, they lost localisation to the
   built-in while their Cramér–Rao bounds said they would win, and the
   nearest-neighbour error ranked all five layouts as the trained GRU did: hence the
   learned objective (see hydrotact/design/_objective.py).
2. **Layouts**: `designed` (learned, on risers); `built-in` (the sensor spec's);
   `regular` (one barometer at the centre facing +z, the others evenly round a ring
   facing outwards at 45°, projected onto the risers' constraints); `random` (the
   inside design's first random feasible start, before optimisation); `designed-d`;
   `designed-inside`.
3. **Retraining**: for each layout a dataset from the same seed and material (the
   ablation's silicone; the same events, presses and sensor variation: only where the
   barometers are differs), and the binned GRU (the defaults of `hydrotact train`)
   trained on each with several seeds, evaluated on each dataset's held-out blocks:
   θ and φ RMSE, the arc-length error, force RMSE, each as mean and spread (standard
   deviation) over the seeds.

Outputs (in --output, default experiments/results/): `layout_design.json` (the
scores, every run's metrics, the settings, the timings), `layout_design.md` (the
table), `layout_design.png` (the metrics per layout with their spread),
`layout_design_layouts.png` (the four layouts inside the cut-open elastomer),
`layout_design_convergence.png` and the designed sensor `layout_design_sensor.json`.
The design, datasets and models are kept under `layout_design.work/` and resume when
the script is run again. Each finished design (its scores and layouts), each layout's
nearest-neighbour check and each trained model's metrics are also written to
`layout_design.runs/`, small files meant to be committed, with the settings they ran
under (and each design's finished starts, `design_NAME.partial/`, which
`design_layout` keeps by its request): a run under the same settings reads them back instead of designing, generating
or training again, so a long run continues on another checkout (as ablation_table1.py's
records do).

Run: `.venv/bin/python experiments/layout_design.py [--events 1000] [--seeds 3] [--smoke]`.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from ablation_table1 import MATERIAL, SMOKE_REGIME, read_record, summarise_metrics, write_record  # noqa: E402  (its neighbour in experiments/: the same silicone, tiny regime, table, records)

from hydrotact._files import atomic_path, digest, write_text_atomic  # noqa: E402
from hydrotact.data import make_material_document, write_material  # noqa: E402
from hydrotact.datasets import DatasetConfig, generate_dataset, load_dataset  # noqa: E402
from hydrotact.design import DesignConfig, calc_neighbour_features, design_layout, make_feasible_region, make_noise_model  # noqa: E402
from hydrotact.models import TrainConfig, calc_skin_radius, evaluate_estimator, save_estimator, train_estimator  # noqa: E402
from hydrotact.sensors import document_text, load_sensor  # noqa: E402

NAME = "layout_design"
LAYOUTS = ("designed", "built-in", "regular", "random", "designed-d", "designed-inside")
DESIGNS = ("risers", "risers-d", "inside")
OBJECTIVE_OF = {"risers": "k", "risers-d": "d", "inside": "d"}
DESIGN_OF = {"designed": "risers", "built-in": "risers", "regular": "risers", "designed-d": "risers-d", "random": "inside", "designed-inside": "inside"}
"""The design whose held-out contacts score each layout (the designs draw their own)."""
SMOKE_SKIPS = ("risers-d", "inside")
"""Designs the smoke run leaves out: risers-d runs the inside design's code path (the
D-optimal objective) under the risers' constraints, which the main design tests; the
inside design's objective and region are the package's defaults, which
tests/test_design.py and notebook 05 run (and it took 40 of the smoke's 127 s)."""
METRICS = ("theta_rmse", "phi_rmse", "arc_length_mean", "fn_rmse", "fx_rmse", "fy_rmse", "fz_rmse", "contact_bce")
RING_TILT_DEG = 45.0
DESIGN_PROBE = "sphere:r=3mm,subdivisions=1"
"""The design's contacts press a coarser 3 mm sphere than the datasets' (measured: with
the regime's own mesh, 96 + 96 linearised contacts grew the design past 22 GB and the
2-core machine's 23 GB killed it; see benchmarks/RESULTS.md, "Layout design")."""


def make_regular_layout(spec, region) -> tuple[np.ndarray, np.ndarray]:
    """One barometer at the board's centre facing +z and the rest evenly round a ring
    (half the elastomer's footprint radius, at the built-in layout's mean height),
    each facing outwards at RING_TILT_DEG; projected onto `region`'s constraints."""
    count = spec.num_taxels
    lo, hi = np.min(region.vertices, axis=0), np.max(region.vertices, axis=0)  # the elastomer's own mesh
    centre = 0.5 * (lo + hi)
    radius = 0.25 * min(hi[0] - lo[0], hi[1] - lo[1])
    height = float(np.mean(spec.taxel_positions_S[:, 2]))
    angles = 2.0 * np.pi * np.arange(count - 1) / (count - 1)
    positions = np.vstack([[centre[0], centre[1], height], np.column_stack([centre[0] + radius * np.cos(angles), centre[1] + radius * np.sin(angles), np.full(count - 1, height)])])
    tilt = np.radians(RING_TILT_DEG)
    axes = np.vstack([[0.0, 0.0, 1.0], np.column_stack([np.sin(tilt) * np.cos(angles), np.sin(tilt) * np.sin(angles), np.full(count - 1, np.cos(tilt))])])
    return region.project_positions(positions), region.project_axes(axes)


def _score(score) -> dict:
    return {"score": score.score, "held_out_score": score.held_out_score, "rms_bound_m": score.rms_bound, "rms_neighbour_error_m": score.rms_neighbour_error}


def _design(spec, args, smoke: bool, work: Path, records: Path, material: dict, design: str) -> dict:
    """One design (`design`: one of DESIGNS), its layouts' sensor files (in
    work/sensors/) and scores, kept as the record records/design_{design}.json: for
    `risers` the designed, built-in and regular layouts; for `risers-d` the designed
    one; for `inside` the designed one and its first random start."""
    settings = {"sensor": digest(document_text(spec)), "material": MATERIAL, "smoke": smoke}  # (the material document carries its creation time)
    if not smoke:
        settings |= {k: getattr(args, k) for k in ("design_contacts", "learned_contacts", "design_batch", "design_steps", "design_restarts", "design_probe")}
    if (document := read_record(records / f"design_{design}.json", settings)) is not None:
        return _write_sensors(document, work)
    mesh = spec.make_mesh(check=False)
    max_height = float(np.max(spec.taxel_positions_S[:, 2]) - np.min(mesh.vertices[:, 2])) if design.startswith("risers") else None
    objective = OBJECTIVE_OF[design]
    if smoke:
        config = DesignConfig(objective=objective, contacts=8, num_rays=8, restarts=1, steps=6, max_height=max_height)
        regime = DatasetConfig(probe=SMOKE_REGIME["probe"])
    else:
        contacts = args.learned_contacts if objective == "k" else args.design_contacts
        config = DesignConfig(objective=objective, contacts=contacts, batch=args.design_batch, num_rays=8, restarts=args.design_restarts, steps=args.design_steps, max_height=max_height)
        regime = DatasetConfig(probe=args.design_probe)
    region = make_feasible_region(mesh, "inside", config.margin, config.spacing, config.max_tilt_deg, max_height)
    regular = make_regular_layout(spec, region)
    result = design_layout(spec, config=config, regime=regime, material=material, compare={"regular": regular}, checkpoint=records / f"design_{design}.partial", progress=not smoke)
    random_index = result.start_names.index("random 0")
    if design == "risers":
        layouts = {"designed": result.spec, "built-in": spec, "regular": _with_positions(spec, *regular, "regular")}
        scores = {"designed": _score(result.designed), "built-in": _score(result.builtin), "regular": _score(result.compared["regular"]), "random start": _score(result.random[random_index - 1])}
    elif design == "risers-d":
        layouts = {"designed-d": result.spec}
        scores = {"designed-d": _score(result.designed), "built-in": _score(result.builtin), "regular": _score(result.compared["regular"]), "random start": _score(result.random[random_index - 1])}
    else:
        layouts = {"designed-inside": result.spec, "random": _with_positions(spec, *result.start_layouts[random_index], "random")}
        scores = {"designed-inside": _score(result.designed), "random": _score(result.random[random_index - 1]), "built-in": _score(result.builtin), "regular": _score(result.compared["regular"])}
    document = {
        "config": config.to_json(), "design_contacts_probe": regime.probe, "scores": scores, "elapsed_s": result.elapsed_s,
        "histories": [np.asarray(h).tolist() for h in result.histories], "start_names": result.start_names,
        "layouts": {name: layout.to_json() for name, layout in layouts.items()},
    }
    write_record(records / f"design_{design}.json", settings, document)
    return _write_sensors(document, work)


def _write_sensors(document: dict, work: Path) -> dict:
    """A design's layouts as sensor files in work/sensors/; the document with their paths."""
    files = {}
    for name, layout in document["layouts"].items():
        files[name] = str(work / "sensors" / f"{name}.json")
        write_text_atomic(Path(files[name]), json.dumps(layout, indent=2) + "\n")
    return {key: value for key, value in document.items() if key != "layouts"} | {"sensors": files}


def _neighbour_baseline(dataset, spec, radius: float | None) -> dict:
    """What the dataset itself allows a simple learner: the five nearest training
    hold samples (by the learned objective's features, asinh of the reading above
    ambient over the noise at zero) estimate each held-out contact sample's angles.
    θ and φ RMSE (rad) and the mean arc length (m) over the held-out contact samples,
    as the GRU is scored: a check, beside the trained GRU, that needs no training."""
    from scipy.spatial import cKDTree

    from hydrotact.models import calc_arc_length

    channels = list(dataset.manifest["channels"])
    ambient, noise = spec.part.ambient_pa, make_noise_model(spec.part)

    def split(name):
        rows = dataset.arrays(name, [*channels, "theta", "phi", "contact", "phase"])
        touching = (rows["contact"] > 0) & np.isfinite(rows["theta"]) & np.isfinite(rows["phi"])
        features = np.asarray(calc_neighbour_features(np.column_stack([rows[c] for c in channels]) - ambient, noise))
        return features, np.column_stack([rows["theta"], rows["phi"]]), touching, rows["phase"] == 2

    train, train_angles, train_touching, hold = split("train")
    chosen = train_touching & hold
    test, test_angles, test_touching, _ = split("test")
    _, index = cKDTree(train[chosen]).query(test[test_touching], k=5)
    estimate, truth = train_angles[chosen][index].mean(axis=1), test_angles[test_touching]
    rmse = np.sqrt(np.mean((estimate - truth) ** 2, axis=0))
    arc = np.asarray(calc_arc_length(truth[:, 0], truth[:, 1], estimate[:, 0], estimate[:, 1], 1.0 if radius is None else radius))
    return {"theta_rmse": float(rmse[0]), "phi_rmse": float(rmse[1]), "arc_length_mean": float(arc.mean())}


def _with_positions(spec, positions, axes, label: str):
    import dataclasses

    moved = dataclasses.replace(spec, name=f"{spec.name}_{label}", description=f"{spec.description} Layout: {label} (experiments/layout_design.py).",
                                taxel_positions_S=np.asarray(positions), taxel_axes_S=np.asarray(axes))
    return load_sensor(moved.to_json(), source=f"the {label} layout")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sensor", default="sphere8")
    parser.add_argument("--events", type=int, default=1000)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--max-epochs", type=int, default=TrainConfig().max_epochs)
    parser.add_argument("--design-contacts", type=int, default=96, help="the D-optimal designs' contacts (and as many held out)")
    parser.add_argument("--learned-contacts", type=int, default=384, help="the learned design's contacts (and as many held out): a nearest-neighbour estimator needs a dense pool")
    parser.add_argument("--design-batch", type=int, default=16)
    parser.add_argument("--design-steps", type=int, default=60)
    parser.add_argument("--design-restarts", type=int, default=2)
    parser.add_argument("--design-probe", default=DESIGN_PROBE, help="the probe of the design's contacts (the datasets use the regime's own)")
    parser.add_argument("--asinh-scale", type=float, help="train the estimators on compressed inputs (TrainConfig.asinh_scale, Pa); "
                        "the results are written as layout_design_asinh.{json,md,png} beside the others, from the same designs and datasets")
    parser.add_argument("--output", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--smoke", action="store_true", help="a tiny design, tiny datasets, one seed, two epochs: for the tests")
    args = parser.parse_args()
    smoke = {}
    if args.smoke:
        args.events, args.seeds, args.max_epochs = 12, 1, 2
        smoke = {"sequence_length": 64, "burn_in": 32, "batch_size": 8}
    output = args.output
    work = output / f"{NAME}.work"
    work.mkdir(parents=True, exist_ok=True)
    records = output / f"{NAME}.runs"
    records.mkdir(exist_ok=True)
    started = time.perf_counter()
    spec = load_sensor(args.sensor)
    material = make_material_document(*MATERIAL, name=NAME)
    material_file = write_material(work / "material.json", material)
    timings = {}
    designs = {}
    inputs = "" if args.asinh_scale is None else f"_asinh{args.asinh_scale:g}"  # the models' folders
    stem = NAME if args.asinh_scale is None else f"{NAME}_asinh"  # the results' files
    run_designs = tuple(name for name in DESIGNS if not (args.smoke and name in SMOKE_SKIPS))
    layouts = tuple(layout for layout in LAYOUTS if DESIGN_OF[layout] in run_designs)
    for name in run_designs:
        t = time.perf_counter()
        designs[name] = _design(spec, args, args.smoke, work, records, material, name)
        timings[f"design {name}"] = time.perf_counter() - t
    sensors = {name: path for design in run_designs for name, path in designs[design]["sensors"].items()}
    scores = {layout: designs[DESIGN_OF[layout]]["scores"][layout] | {"pool": DESIGN_OF[layout]} for layout in layouts}
    radius = calc_skin_radius(spec)
    runs, baselines = [], {}
    for layout in layouts:
        config = DatasetConfig(events=args.events, **(SMOKE_REGIME if args.smoke else {}))
        # A layout's records hold for its sensor, dataset regime, material and training settings.
        settings = {"sensor": digest(Path(sensors[layout]).read_text()), "dataset": config.to_json(), "material": MATERIAL, "max_epochs": args.max_epochs, "smoke": args.smoke}
        models = [work / f"{layout}_gru_binned{inputs}_{seed}" for seed in range(args.seeds)]
        baselines[layout] = read_record(records / f"{layout}_neighbours.json", settings)
        kept = [read_record(records / f"{model.name}.json", settings | {"asinh_scale": args.asinh_scale}) for model in models]
        if baselines[layout] is not None and all(run is not None for run in kept):
            runs.extend(kept)
            print(f"{layout}: the nearest-neighbour check and {len(kept)} model(s) read back from {records}", flush=True)
            continue
        t = time.perf_counter()
        folder = work / f"{layout}_dataset"
        generate_dataset(sensors[layout], folder, material=material_file, config=config, progress=not args.smoke)
        dataset = load_dataset(folder)
        timings[f"generate {layout}"] = time.perf_counter() - t
        rate = float(dataset.manifest["config"]["rate_hz"])
        if baselines[layout] is None:
            baselines[layout] = _neighbour_baseline(dataset, spec, radius)
            write_record(records / f"{layout}_neighbours.json", settings, baselines[layout])
        for seed, (model, run) in enumerate(zip(models, kept)):
            if run is None:
                model.mkdir(exist_ok=True)
                t = time.perf_counter()
                trained = train_estimator(dataset, load_sensor(sensors[layout]), TrainConfig(seed=seed, max_epochs=args.max_epochs, asinh_scale=args.asinh_scale, **smoke), folder=model)
                save_estimator(trained, model, sensors[layout])
                result = evaluate_estimator(trained, dataset.blocks("test"), rate, radius)
                run = {"layout": layout, "seed": seed, "epochs": len(trained.history), "best_epoch": trained.best_epoch,
                       "wall_seconds": time.perf_counter() - t, "metrics": result["metrics"]}
                write_record(records / f"{model.name}.json", settings | {"asinh_scale": args.asinh_scale}, run)
            runs.append(run)
            print(f"{layout} seed {seed}: " + ", ".join(f"{k} {v:.3g}" for k, v in run["metrics"].items()), flush=True)
    table = _table(layouts, runs, scores, baselines)
    document = {
        "settings": {"sensor": args.sensor, "events": args.events, "seeds": args.seeds, "max_epochs": args.max_epochs, "asinh_scale": args.asinh_scale, "smoke": args.smoke,
                     "material": MATERIAL},
        "designs": designs, "table": table, "runs": runs, "timings_s": timings | {"total": time.perf_counter() - started},
    }
    output.mkdir(parents=True, exist_ok=True)
    write_text_atomic(output / f"{stem}.json", json.dumps(document, indent=2) + "\n")
    inputs_text = "z-scores of the readings (the paper's)" if args.asinh_scale is None else f"asinh of the reading above rest over {args.asinh_scale:g} Pa, z-scored"
    how = "; ".join(f"{name}: objective {designs[name]['config']['objective']}, {designs[name]['config']['contacts']} contacts (+ as many held out)" for name in run_designs)
    settings = (f"{args.sensor}; {args.events} events per dataset, {args.seeds} seed(s), at most {args.max_epochs} epochs{' (smoke)' if args.smoke else ''}; "
                f"estimator inputs: {inputs_text}; "
                f"designs: {how}; each {designs['risers']['config']['restarts']} random starts, "
                f"{designs['risers']['config']['steps']} steps, risers at most {designs['risers']['config']['max_height'] * 1e3:.3g} mm high; "
                f"{document['timings_s']['total'] / 60:.0f} min in this invocation"
                f" (designs, datasets and models read back from the work folder or the records not counted).")
    write_text_atomic(output / f"{stem}.md", settings + "\n\n" + _markdown(table))
    _plot(table, output / f"{stem}.png")
    written = ".json, .md, .png"
    if args.asinh_scale is None:  # the designs' own files (the same for either estimator)
        from hydrotact.viz import plot_design_convergence, render_layouts

        write_text_atomic(output / f"{NAME}_sensor.json", Path(sensors["designed"]).read_text())
        render_layouts(spec.make_mesh(check=False), {name: load_sensor(sensors[name]) for name in layouts}, output / f"{NAME}_layouts.png")
        main = designs["risers"]  # the main design's climbs (the others climb other objectives)
        plot_design_convergence(main["histories"], main["start_names"], output / f"{NAME}_convergence.png", main["config"]["objective"])
        written += ", _layouts.png, _convergence.png, _sensor.json"
    print(settings + "\n\n" + _markdown(table))
    print(f"written {output / stem}{written}")


def _table(layouts, runs: list, scores: dict, baselines: dict) -> list:
    table = []
    for layout in layouts:
        members = [run for run in runs if run["layout"] == layout]
        entry = {"layout": layout, "seeds": len(members)} | {f"design_{k}": v for k, v in scores[layout].items()}
        entry |= {f"neighbours_{k}": v for k, v in baselines[layout].items()}
        table.append(entry | summarise_metrics(members, METRICS))
    return table


def _markdown(table: list) -> str:
    head = ("| layout | design score (held out; pool) | RMS bound (mm) | nearest-neighbour error (mm) | dataset's 5-NN θ, φ (rad), arc (mm) | "
            + " | ".join(METRICS) + " |\n|---|---:|---:|---:|---:|" + "---:|" * len(METRICS) + "\n")
    cell = lambda e, n: f"{e[n]['mean']:.3g} ± {e[n]['std']:.2g}" if n in e else "-"
    body = "".join(
        f"| {e['layout']} | {e['design_held_out_score']:.4g} ({e['design_pool']}) | {e['design_rms_bound_m'] * 1e3:.3g} | {e['design_rms_neighbour_error_m'] * 1e3:.3g} | "
        f"{e['neighbours_theta_rmse']:.3g}, {e['neighbours_phi_rmse']:.3g}, {e['neighbours_arc_length_mean'] * 1e3:.3g} | "
        + " | ".join(cell(e, n) for n in METRICS) + " |\n" for e in table
    )
    return ("Design score on the held-out contacts of the design named (higher is better; each design draws its own contacts and has its own objective, "
            "so scores compare within a pool): risers, minus the mean squared leave-one-out error of a nearest-neighbour estimator (mm²); risers-d and inside, "
            "the mean log det of the Fisher information of (contact point, force). "
            "RMS bound: the Cramér–Rao bound on the localisation error; nearest-neighbour error: the RMS leave-one-out error of that estimator, on the same pool; "
            "dataset's 5-NN: each held-out contact sample's angles estimated by its five nearest training hold samples (no training). "
            "After training the binned GRU on each layout's dataset: RMSE in N (forces) and rad "
            "(angles), arc length in m, contact BCE; mean ± standard deviation over seeds.\n\n" + head + body)


def _plot(table: list, path: Path) -> None:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(11, 4))
    axes = figure.subplots(1, 3)
    x = np.arange(len(table))
    panels = ((axes[0], ("theta_rmse", "phi_rmse"), "held-out RMSE (rad)", 1.0), (axes[1], ("arc_length_mean",), "mean arc-length error (mm)", 1e3),
              (axes[2], ("fn_rmse", "fx_rmse", "fy_rmse", "fz_rmse"), "held-out RMSE (N)", 1.0))
    for axis, names, label, scale in panels:
        for k, name in enumerate(names):
            means = [e[name]["mean"] * scale if name in e else np.nan for e in table]
            spread = [e[name]["std"] * scale if name in e else 0.0 for e in table]
            axis.bar(x + (k - len(names) / 2 + 0.5) * 0.8 / len(names), means, 0.8 / len(names), yerr=spread, capsize=2, label=name.removesuffix("_rmse").removesuffix("_mean"))
        axis.set_xticks(x, [e["layout"] for e in table], fontsize=8, rotation=20, ha="right")
        axis.set_ylabel(label)
        axis.legend(fontsize=7)
    figure.suptitle("The binned GRU trained on each layout's dataset (mean and spread over seeds)", fontsize=9)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)


if __name__ == "__main__":
    sys.exit(main())
