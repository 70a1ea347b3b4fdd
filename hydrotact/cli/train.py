"""`hydrotact train`: a contact estimator trained on a generated dataset
(hydrotact.models.train_estimator), saved with its training curve.

Interrupted runs resume: started again with the same arguments into the same folder,
training continues from the last epoch's checkpoint."""

from pathlib import Path

from ._arguments import number
from ._output import print_report


def _sizes(text: str) -> tuple:
    import argparse

    try:
        sizes = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected sizes separated by commas (e.g. 22,22), got {text!r}") from None
    return sizes


def _names(text: str) -> tuple:
    import argparse

    from ..models import REGRESSION_TARGETS

    names = tuple(part.strip() for part in text.split(",") if part.strip())
    unknown = [name for name in names if name not in REGRESSION_TARGETS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{unknown[0] if unknown else text!r}: targets are names separated by commas, of {', '.join(REGRESSION_TARGETS)}")
    return names


def add_parser(subparsers):
    from ..models import ARCHITECTURES, SCHEDULES, TrainConfig

    d = TrainConfig.__dataclass_fields__
    default = lambda name: d[name].default
    parser = subparsers.add_parser(
        "train", help="train a contact estimator (binned GRU by default) on a generated dataset",
        description="Trains on the dataset's training split, validates on its held-out split after every epoch, stops early, "
        "keeps the best epoch. Writes model.json, weights.npz, checkpoint.npz and training_curve.png to the output folder; "
        "an interrupted run resumes when started again with the same arguments.",
    )
    parser.add_argument("dataset", type=Path, metavar="DATASET", help="a dataset folder from hydrotact generate")
    parser.add_argument("--architecture", choices=ARCHITECTURES, default=default("architecture"), help=f"the estimator (default {default('architecture')}: two GRU layers)")
    parser.add_argument("--targets", type=_names, default=default("targets"), metavar="T1,T2",
                        help="what it estimates besides contact (and the angles on a sensor with them): fx, fy, fz, fn (N), the contact position x, y "
                        "and the indentation depth (m), from the dataset's columns (default fx,fy,fz,fn; e.g. x,depth for a strip pressed by a stage)")
    parser.add_argument("--plain", action="store_true", help="regress the contact angles instead of classifying them into pi/16 bins")
    parser.add_argument("--hidden", type=_sizes, metavar="H1,H2", help="hidden sizes (default: the GRU's largest two equal layers within 6000 parameters; the paper's sizes for rnn and mlp)")
    parser.add_argument("--cover", choices=("whole", "floor"), default=default("cover"), help="angle bins cover the whole ranges, or the paper's floor count (default whole)")
    parser.add_argument("--sequence-length", type=int, default=default("sequence_length"), metavar="N", help=f"labelled samples per training sequence (default {default('sequence_length')})")
    parser.add_argument("--burn-in", type=int, default=default("burn_in"), metavar="N", help=f"context samples before them, unlabelled (default {default('burn_in')})")
    parser.add_argument("--batch-size", type=int, default=default("batch_size"), metavar="N", help=f"sequences per step (default {default('batch_size')}, the paper's)")
    parser.add_argument("--learning-rate", type=number, default=default("learning_rate"), metavar="R", help=f"Adam's learning rate (default {default('learning_rate'):g})")
    parser.add_argument("--schedule", choices=SCHEDULES, default=default("schedule"), help=f"learning-rate schedule over --max-epochs (default {default('schedule')})")
    parser.add_argument("--asinh-scale", type=number, metavar="PA",
                        help="compress the readings first, asinh((reading - rest) / PA), so light presses move the inputs too "
                        "(e.g. 20; default: none, the paper's z-scores of the readings)")
    parser.add_argument("--max-epochs", type=int, default=default("max_epochs"), metavar="N", help=f"the most epochs (default {default('max_epochs')})")
    parser.add_argument("--patience", type=int, default=default("patience"), metavar="N", help=f"stop after this many epochs without a better validation loss (default {default('patience')})")
    parser.add_argument("--last-epoch", action="store_true", help="keep the last epoch's parameters, not the best validation epoch's")
    parser.add_argument("--seed", type=int, default=default("seed"), metavar="K", help=f"seed of the initialisation and the shuffles (default {default('seed')})")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="DIR", help="the model folder")
    parser.add_argument("--no-plots", action="store_true", help="skip the training-curve PNG")
    parser.add_argument("--json", action="store_true", help="print the report as JSON (and no progress bar)")
    return parser


def run(args) -> None:
    from .._files import check_output, removed_if_refused
    from ..datasets import load_dataset
    from ..models import TrainConfig, count_macs, count_parameters, save_estimator, train_estimator
    from ..sensors import load_sensor

    config = TrainConfig(
        architecture=args.architecture, binned=not args.plain, hidden=args.hidden, cover=args.cover, sequence_length=args.sequence_length,
        burn_in=args.burn_in, batch_size=args.batch_size, learning_rate=args.learning_rate, schedule=args.schedule,
        max_epochs=args.max_epochs, patience=args.patience, restore_best=not args.last_epoch, seed=args.seed,
        asinh_scale=args.asinh_scale, targets=args.targets,
    )
    check_output(args.output, directory=True, what="the model")
    dataset = load_dataset(args.dataset)
    sensor = load_sensor(dataset.manifest["sensor"]["spec"])
    with removed_if_refused(args.output):  # a killed run keeps its checkpoint to resume from
        args.output.mkdir(parents=True, exist_ok=True)
        trained = train_estimator(dataset, sensor, config, folder=args.output, progress=not args.json)
    path = save_estimator(trained, args.output, sensor.name)
    plots = []
    if not args.no_plots:
        from ..viz import plot_training_curve

        plots.append(args.output / "training_curve.png")
        plot_training_curve(trained.history, plots[-1], trained.best_epoch, f"{sensor.name}: {config.architecture} {trained.spec.hidden}")
    best = trained.history[trained.best_epoch]
    report = {
        "model": str(path), "sensor": sensor.name, "architecture": trained.spec.architecture, "hidden": ",".join(map(str, trained.spec.hidden)),
        "targets": ",".join(trained.spec.targets), "binned": trained.spec.binned, "parameters": count_parameters(trained.spec), "macs_per_step": count_macs(trained.spec),
        "epochs": len(trained.history), "best_epoch": trained.best_epoch, "stopped": trained.stopped,
        "validation_loss": best["validation_loss"], **{f"validation_{k}": v for k, v in best["validation_metrics"].items()},
        "seconds": sum(entry["seconds"] for entry in trained.history), "plots": ", ".join(map(str, plots)) or "none",
    }
    print_report(f"estimator for {sensor.name}", report, args.json)
