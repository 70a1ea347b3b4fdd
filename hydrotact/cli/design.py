"""`hydrotact design`: a barometer layout designed by gradient
(hydrotact.design.design_layout), written as a sensor JSON that every other command
reads, with its pictures and report.

Interrupted runs resume: each finished start is kept in `LAYOUT.json.partial/`, and the
same command started again picks up after the last one (the folder goes on success)."""

from pathlib import Path

from ._arguments import number, number_pair
from ._output import print_report

PER_CONTACT = ("localisation_bounds", "neighbour_errors")
"""LayoutScore's per-contact arrays: in the pictures, not in the report."""


def add_parser(subparsers):
    from ..datasets import TARGETS, DatasetConfig
    from ..design import DesignConfig

    d = DesignConfig.__dataclass_fields__
    default = lambda name: d[name].default
    parser = subparsers.add_parser(
        "design", help="design where the barometers go and how they face, by gradient of the information their readings carry",
        description="Maximises what the barometers' readings say about where a contact is and how hard it presses "
        "(D-optimal information, the A-optimal Cramer-Rao bound on localisation, or the localisation error of an estimator learned "
        "from the readings), over contacts of the dataset regime, from several feasible "
        "starts, under the constraints (inside the elastomer or on the board, a margin, a spacing, unit axes within a tilt). "
        "Writes the designed sensor JSON, before/after renders, the convergence and a map of the predicted localisation error.",
    )
    parser.add_argument("--sensor", required=True, metavar="S", help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a sensor JSON file")
    parser.add_argument("--barometers", type=int, metavar="N", help="how many barometers (default: as many as the sensor has)")
    parser.add_argument("--objective", default=default("objective"), choices=["d", "a", "k"],
                        help="d: information volume (D-optimal); a: localisation bound (A-optimal); k: the leave-one-out localisation error of a "
                        "nearest-neighbour estimator learned from the readings (ranks layouts as a trained estimator does) (default: %(default)s)")
    parser.add_argument("--balance", type=number, default=default("balance"), metavar="P",
                        help="k: the p-norm over the estimated target's components (theta and phi, or x, y, z) of their mean squared errors; "
                        "1 sums them, a larger p leans on the worst (default %(default)g)")
    parser.add_argument("--placement", choices=["inside", "board"], help="ports inside the elastomer or on the board (default: where the sensor's are)")
    parser.add_argument("--spacing", type=number, default=default("spacing"), metavar="M", help=f"least distance between ports, m (default {default('spacing'):g})")
    parser.add_argument("--margin", type=number, default=default("margin"), metavar="M", help=f"least distance from a port to the elastomer's boundary, m (default {default('margin'):g})")
    parser.add_argument("--max-tilt", type=number, default=default("max_tilt_deg"), metavar="DEG", help=f"largest tilt of an axis from +z (default {default('max_tilt_deg'):g})")
    parser.add_argument("--max-height", type=number, metavar="M", help="ports on risers: the highest a port may sit above the board, m (default: anywhere inside)")
    parser.add_argument("--field-sizes", action="store_true", help="design each receptive field's size too")
    parser.add_argument("--material", type=Path, metavar="MATERIAL.json", help="the elastomer (its E(0) is used); default: elastic, --modulus")
    parser.add_argument("--modulus", type=number, metavar="E", help="elastic modulus in Pa, without --material (default 1e7, the dataset generator's)")
    parser.add_argument("--probe", metavar="SPEC", help="the indenter (default: the dataset regime's, sphere:r=3mm)")
    parser.add_argument(
        "--expansions", type=int, default=default("expansions"), metavar="N",
        help=f"elastic barometers: rounds per start, each on the readings linearised at its start (default {default('expansions')})")
    parser.add_argument(
        "--trust-radius", type=number, default=default("trust_radius"), metavar="M",
        help=f"elastic barometers: the furthest a round moves a port from where it was linearised, m (default {default('trust_radius'):g})")
    parser.add_argument("--target", choices=list(TARGETS), default=DatasetConfig().target, help="the contacts pressed to the dataset regime's forces (default) or to its depths (the paper's regime)")
    parser.add_argument("--depth-range", type=number_pair, metavar="LOW,HIGH", help="target depths with --target depth, m (default: the dataset regime's, 0.0001,0.002)")
    parser.add_argument("--contacts", type=int, default=default("contacts"), metavar="N", help=f"contacts designed for, and as many held out (default {default('contacts')})")
    parser.add_argument("--batch", type=int, default=default("batch"), metavar="N", help=f"contacts per optimiser step, a fresh draw from the pool each step (default {default('batch')})")
    parser.add_argument("--rays", type=int, default=default("num_rays"), metavar="N", help=f"rays per receptive field (default {default('num_rays')})")
    parser.add_argument("--noise", type=number, metavar="PA", help="barometer RMS noise in Pa (default: the part's)")
    parser.add_argument(
        "--noise-floor", type=number, default=default("noise_floor"), metavar="PA",
        help=f"a cast barometer's drift, creep and hysteresis as noise, Pa (default {default('noise_floor'):g})")
    parser.add_argument("--relative-noise", type=number, default=default("relative_noise"), metavar="F", help=f"noise floor as a fraction of the reading (default {default('relative_noise'):g})")
    parser.add_argument("--restarts", type=int, default=default("restarts"), metavar="K", help=f"random feasible starts besides the sensor's own (default {default('restarts')})")
    parser.add_argument("--steps", type=int, default=default("steps"), metavar="N", help=f"optimiser steps per start (default {default('steps')})")
    parser.add_argument("--seed", type=int, default=default("seed"), metavar="K", help=f"seed of every draw (default {default('seed')})")
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="LAYOUT.json", help="the designed sensor JSON (pictures and a report beside it)")
    parser.add_argument("--no-plots", action="store_true", help="skip the pictures")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    import dataclasses
    import json
    import shutil

    from .._files import check_output, removed_if_refused, write_text_atomic
    from ..datasets import DatasetConfig
    from ..design import DesignConfig, design_layout
    from ..design._config import OBJECTIVE_DESCRIPTIONS, OBJECTIVE_SCORES
    from ..sensors import document_text

    output = check_output(args.output, suffixes=(".json",), what="the designed sensor")
    config = DesignConfig(
        objective=args.objective, balance=args.balance,
        contacts=args.contacts, batch=args.batch, num_rays=args.rays, relative_noise=args.relative_noise, noise_floor=args.noise_floor, noise_rms=args.noise,
        placement=args.placement, margin=args.margin, spacing=args.spacing, max_tilt_deg=args.max_tilt, max_height=args.max_height, field_sizes=args.field_sizes,
        restarts=args.restarts, steps=args.steps, seed=args.seed, expansions=args.expansions, trust_radius=args.trust_radius,
    )
    regime = {"target": args.target} | ({} if args.probe is None else {"probe": args.probe})
    if args.depth_range is not None:
        regime["depth_range"] = args.depth_range
    regime = DatasetConfig(**regime)
    partial = output.with_name(output.name + ".partial")
    with removed_if_refused(partial):  # a killed run keeps its finished starts to resume
        design = design_layout(
            args.sensor, args.barometers, config=config, regime=regime, material=args.material, modulus=args.modulus, checkpoint=partial, progress=not args.json
        )
    write_text_atomic(output, document_text(design.spec))
    stem = output.with_suffix("")
    scores = {"designed": design.designed} | ({"built-in": design.builtin} if design.builtin is not None else {})
    report_document = {
        "sensor": design.start_spec.name, "designed_sensor": str(output), "config": design.config.to_json(), "regime": design.regime.to_json(),
        "scores": {name: {k: v for k, v in dataclasses.asdict(s).items() if k not in PER_CONTACT} for name, s in scores.items()},
        "random_starts": [{k: v for k, v in dataclasses.asdict(s).items() if k not in PER_CONTACT} for s in design.random],
        "elapsed_s": design.elapsed_s,
    }
    write_text_atomic(f"{stem}_report.json", json.dumps(report_document, indent=2) + "\n")
    pictures = []
    if not args.no_plots:
        from ..viz import plot_design_convergence, plot_localisation_maps, render_layouts

        before = "built-in" if design.builtin is not None else "start"
        render_layouts(design.start_spec.make_mesh(check=False), {before: design.start_spec, "designed": design.spec}, f"{stem}_layouts.png")
        plot_design_convergence(design.histories, design.start_names, f"{stem}_convergence.png", design.config.objective)
        learned = design.config.objective == "k"
        errors = {name: s.neighbour_errors if learned else s.localisation_bounds for name, s in reversed(scores.items())}
        plot_localisation_maps(design.held_out_points_S, errors, design.start_spec, f"{stem}_error_map.png", "nearest-neighbour estimator" if learned else "Cramér–Rao bound")
        pictures = [f"{stem}_layouts.png", f"{stem}_convergence.png", f"{stem}_error_map.png"]
    best_random = max(design.random, key=lambda s: s.held_out_score) if design.random else None
    report = {
        "designed_sensor": str(output),
        "barometers": design.spec.num_taxels,
        "objective": f"{OBJECTIVE_DESCRIPTIONS[config.objective]}; score: {OBJECTIVE_SCORES[config.objective]}",
        "designed_score": f"{design.designed.score:.5g} (held out {design.designed.held_out_score:.5g})",
        "built_in_score": "n/a (other count)" if design.builtin is None else f"{design.builtin.score:.5g} (held out {design.builtin.held_out_score:.5g})",
        "best_random_score": "none" if best_random is None else f"{best_random.score:.5g} (held out {best_random.held_out_score:.5g})",
        "rms_localisation_bound_mm": f"{design.designed.rms_bound * 1e3:.3g}" + ("" if design.builtin is None else f" (built-in {design.builtin.rms_bound * 1e3:.3g})"),
        "rms_neighbour_error_mm": f"{design.designed.rms_neighbour_error * 1e3:.3g}" + ("" if design.builtin is None else f" (built-in {design.builtin.rms_neighbour_error * 1e3:.3g})"),
        "elapsed_s": design.elapsed_s,
        "report": f"{stem}_report.json",
        "pictures": ", ".join(pictures) or "none",
    }
    shutil.rmtree(partial, ignore_errors=True)
    print_report(f"layout designed for {design.start_spec.name}", report, args.json)
