"""Training an estimator on a generated dataset (a host loop around pure, jitted steps).

The data: the dataset's training blocks cut into sequences of `sequence_length`
labelled samples, each after `burn_in` samples of context (:func:`make_sequences`),
inputs normalised with the training split's per-channel mean and standard deviation.
Validation is the dataset's held-out split, cut the same way, evaluated whole after
every epoch; training stops early after `patience` epochs without a better validation
loss, and the best epoch's parameters are kept.

The optimiser is optax's Adam after global-norm clipping, with a constant or cosine-
decayed learning rate. The paper trained with Adam at 1e-5 to 5e-5 for about two hours
on a desktop GPU; the default here, 2e-3 decayed over the epochs, reaches its plateau
in minutes on a CPU for estimators of a few thousand parameters.

Resumable: with a `folder`, the state after each epoch (parameters, optimiser state,
the best parameters, the history) is written atomically to `checkpoint.npz`; running
the same training again continues from it, with the same shuffles (each epoch's
order comes from the seed and the epoch's number), and ends as an uninterrupted run.
"""

import dataclasses
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._errors import HydrotactError
from .._files import atomic_path, digest
from ._estimator import FORCES, EstimatorSpec, calc_estimator_sequence, calc_target_scaling, check_budget, check_targets, init_estimator, make_estimator_spec
from ._loss import DEFAULT_WEIGHTS, calc_loss, calc_table_metrics
from ._sequences import Normaliser, make_sequences, target_labels

SCHEDULES = ("constant", "cosine")
CHECKPOINT = "checkpoint.npz"


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """How an estimator is trained (every field is saved with the model).

    **Model:** `architecture` ("gru", "rnn", "mlp"), `binned` angle heads, `hidden`
    sizes (None: the default of :func:`make_estimator_spec`), `cover` of the bins,
    the regression `targets` (:data:`hydrotact.models.REGRESSION_TARGETS`; the four
    forces by default; e.g. ("x", "depth") for a strip pressed by a stage).
    **Data:** `sequence_length` labelled samples per sequence after `burn_in` samples
    of context. **Optimiser:** `batch_size` sequences per step (the paper's 50),
    `learning_rate`, `schedule` ("constant" or "cosine" over `max_epochs`),
    `clip_norm` (global gradient norm), loss `weights` (force, angle, contact; the
    paper's contact weight of 10). **Inputs:** `asinh_scale` None, the paper's
    z-scores of the readings, or a pressure (Pa) that compresses them first,
    asinh((y - rest) / asinh_scale) (see :class:`Normaliser`; on sphere8 with 20 Pa,
    the noise a design assumes at zero, the held-out φ RMSE fell from 0.389 to 0.318
    rad on the built-in layout and from 0.380 to 0.272 on a designed one, and the Fn
    RMSE rose by 4 and 13 %: benchmarks/RESULTS.md). **Stopping:** `max_epochs`, `patience` (epochs
    without a better validation loss), `restore_best` (keep the best validation
    epoch's parameters, the default, or the last epoch's). `seed` of the
    initialisation and the shuffles.
    """

    architecture: str = "gru"
    binned: bool = True
    hidden: tuple | None = None
    cover: str = "whole"
    sequence_length: int = 256
    burn_in: int = 128
    batch_size: int = 50
    learning_rate: float = 2e-3
    schedule: str = "cosine"
    clip_norm: float = 1.0
    weights: tuple = tuple(DEFAULT_WEIGHTS.items())
    max_epochs: int = 100
    patience: int = 8
    restore_best: bool = True
    asinh_scale: float | None = None
    seed: int = 0
    targets: tuple = FORCES

    def __post_init__(self):
        try:
            check_targets(self.targets)
        except ValueError as error:
            raise HydrotactError(f"targets: {error}") from None
        if self.schedule not in SCHEDULES:
            raise HydrotactError(f"schedule {self.schedule!r}: use one of {', '.join(SCHEDULES)}")
        for name in ("sequence_length", "batch_size", "max_epochs", "patience"):
            if int(getattr(self, name)) < 1:
                raise HydrotactError(f"{name.replace('_', '-')}: must be at least 1, got {getattr(self, name)}")
        if self.burn_in < 0:
            raise HydrotactError(f"burn-in: must not be negative, got {self.burn_in}")
        if self.hidden is not None and (not len(self.hidden) or any(isinstance(size, bool) or not isinstance(size, int | np.integer) or size < 1 for size in self.hidden)):
            raise HydrotactError(f"hidden: sizes must be whole numbers of at least 1, got {','.join(map(str, self.hidden)) or 'none'}")
        if not (0.0 < self.learning_rate < 1.0):
            raise HydrotactError(f"learning-rate: must lie in (0, 1), got {self.learning_rate:g}")
        if self.asinh_scale is not None and (isinstance(self.asinh_scale, bool) or not isinstance(self.asinh_scale, int | float) or not (np.isfinite(self.asinh_scale) and self.asinh_scale > 0.0)):
            raise HydrotactError(f"asinh-scale: must be a positive pressure in Pa, got {self.asinh_scale!r}")
        unknown = set(dict(self.weights)) - set(DEFAULT_WEIGHTS)
        if unknown:
            raise HydrotactError(f"weights: unknown term {sorted(unknown)[0]!r} (use {', '.join(DEFAULT_WEIGHTS)})")

    def to_json(self) -> dict:
        document = dataclasses.asdict(self)
        document["hidden"] = None if self.hidden is None else list(self.hidden)
        document["weights"] = dict(self.weights)
        document["targets"] = list(self.targets)
        return document


@dataclasses.dataclass(frozen=True)
class TrainedEstimator:
    """A trained estimator: its `spec`, `params` (the best epoch's, or the last's
    where the config does not `restore_best`), the input
    `normaliser` and `channels` (dataset columns, in input order), the `config`, and
    the `history` (per epoch: training and validation loss and terms, validation
    Table I metrics, seconds), `best_epoch` and why it `stopped`."""

    spec: EstimatorSpec
    params: dict
    normaliser: Normaliser
    channels: tuple
    config: TrainConfig
    history: list
    best_epoch: int
    stopped: str


def _flat(tree) -> list:
    return [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(tree)]


def _unflat(like, leaves):
    treedef = jax.tree_util.tree_structure(like)
    return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(leaf) for leaf in leaves])


def _make_optimiser(config: TrainConfig, steps_per_epoch: int):
    if config.schedule == "cosine":
        rate = optax.cosine_decay_schedule(config.learning_rate, decay_steps=config.max_epochs * steps_per_epoch, alpha=0.05)
    else:
        rate = config.learning_rate
    return optax.chain(optax.clip_by_global_norm(config.clip_norm), optax.adam(rate))


def _make_functions(spec: EstimatorSpec, optimiser, weights: dict):
    def loss(params, inputs, targets):
        raw = jax.vmap(lambda x: calc_estimator_sequence(spec, params, x)[1])(inputs)
        return calc_loss(spec, raw, targets, weights)

    @jax.jit
    def step(params, state, inputs, targets):
        (value, terms), grads = jax.value_and_grad(loss, has_aux=True)(params, inputs, targets)
        updates, state = optimiser.update(grads, state, params)
        return optax.apply_updates(params, updates), state, value, terms

    @jax.jit
    def evaluate(params, inputs, targets):
        raw = jax.vmap(lambda x: calc_estimator_sequence(spec, params, x)[1])(inputs)
        value, terms = calc_loss(spec, raw, targets, weights)
        return value, terms, calc_table_metrics(spec, raw, targets)

    return step, evaluate


def _request(config: TrainConfig, data: dict) -> str:
    """What a checkpoint belongs to: the settings and the data (a resumed run must match)."""
    return json.dumps({"config": config.to_json(), "data": data}, sort_keys=True)


def _load_checkpoint(path: Path, request: str):
    try:
        with np.load(path, allow_pickle=False) as saved:
            stored = {name: saved[name] for name in saved.files}
    except (OSError, ValueError, EOFError) as error:
        raise HydrotactError(f"{path}: unreadable checkpoint ({error}); delete it to train from the start") from None
    if str(stored.get("request", "")) != request:
        raise HydrotactError(f"{path}: a checkpoint of another training (other settings or dataset); use another output folder, or delete it")
    return stored


def train_estimator(dataset, sensor, config: TrainConfig | None = None, folder=None, progress: bool = False, on_epoch=None) -> TrainedEstimator:
    """Train an estimator on `dataset` (a :class:`hydrotact.datasets.Dataset`) for
    `sensor` (a :class:`hydrotact.sensors.SensorSpec`: its angle ranges size the
    bins). With `folder`, resumable (see the module); `on_epoch(entry)` after each
    epoch's checkpoint. Returns a TrainedEstimator."""
    config = config or TrainConfig()
    channels = tuple(dataset.channels)
    train = dataset.arrays("train")
    held_out = dataset.arrays("test")
    if not train or not held_out:
        raise HydrotactError(f"{dataset.folder}: training needs both a train and a test split")
    target_labels(train, config.targets, str(dataset.folder))  # each target has its label column
    try:
        scaling = calc_target_scaling(train, config.targets, train.get("contact"))
    except ValueError as error:
        raise HydrotactError(f"{dataset.folder}: {error}") from None
    spec = make_estimator_spec(sensor, config.architecture, config.binned, config.hidden, config.cover, config.targets, scaling)
    check_budget(spec)
    if spec.num_inputs != len(channels):
        raise HydrotactError(f"{dataset.folder}: {len(channels)} barometer columns, the sensor {sensor.name!r} has {spec.num_inputs}")
    normaliser = _fit_normaliser(train, channels, config.asinh_scale)
    params = init_estimator(spec, jax.random.PRNGKey(config.seed))
    request = _request(config, {"dataset": dataset.manifest.get("request_digest"), "rows": dataset.num_rows})
    return _fit(spec, params, normaliser, channels, train, held_out, config, folder, progress, on_epoch, request)


def join_recordings(blocks: list) -> dict:
    """Recordings (dicts of equal-length columns) as one set of arrays with
    `block_starts`, as :meth:`Dataset.arrays` gives them."""
    names = set.intersection(*(set(block) for block in blocks))
    joined = {name: np.concatenate([np.asarray(block[name]) for block in blocks]) for name in names}
    joined["block_starts"] = np.cumsum([0] + [len(block["time"]) for block in blocks])[:-1]
    return joined


def fine_tune_estimator(
    trained: TrainedEstimator, train_blocks: list, validation_blocks: list, config: TrainConfig | None = None,
    renormalise: bool = True, folder=None, progress: bool = False, on_epoch=None,
) -> TrainedEstimator:
    """Continue training a pretrained estimator on a few recordings of a real sensor
    (dicts of columns: its channels and the labels, e.g. `BarometerLog.columns`),
    validated on `validation_blocks`. The model keeps its architecture; the optimiser
    settings and stopping come from `config` (its model and input fields are ignored). With
    `renormalise`, the inputs are normalised with the new recordings' statistics (a
    sensor's offsets and gains differ from unit to unit), else with the pretrained ones."""
    config = config or TrainConfig()
    channels = trained.channels
    for k, block in enumerate([*train_blocks, *validation_blocks]):
        missing = [name for name in (*channels, "contact") if name not in block]
        if missing:
            raise HydrotactError(f"recording {k + 1}: no column {missing[0]!r}; fine-tuning needs the channels {', '.join(channels)} and the contact label")
        target_labels(block, trained.spec.targets, f"recording {k + 1}")
    train, held_out = join_recordings(train_blocks), join_recordings(validation_blocks)
    normaliser = _fit_normaliser(train, channels, trained.normaliser.scale) if renormalise else trained.normaliser
    config = dataclasses.replace(config, architecture=trained.spec.architecture, binned=trained.spec.binned, hidden=trained.spec.hidden, targets=trained.spec.targets)
    data = _digest_arrays([train[name] for name in sorted(train)] + [held_out[name] for name in sorted(held_out)])
    request = _request(config, {"fine_tune": data, "pretrained": _digest_arrays(_flat(trained.params)), "renormalise": renormalise})
    return _fit(trained.spec, trained.params, normaliser, channels, train, held_out, config, folder, progress, on_epoch, request)


def _fit_normaliser(train: dict, channels, scale: float | None) -> Normaliser:
    """The training split's normaliser; a compressing one rests on its no-contact samples."""
    resting = np.asarray(train["contact"]) <= 0 if "contact" in train else None
    return Normaliser.fit(np.column_stack([train[name] for name in channels]), scale, resting)


def _digest_arrays(arrays: list) -> str:
    return digest(*(part for array in arrays for part in (str((np.asarray(array).dtype, np.shape(array))), np.ascontiguousarray(array).tobytes())))


def _fit(spec, params, normaliser, channels, train, held_out, config, folder, progress, on_epoch, request) -> TrainedEstimator:
    from tqdm.auto import tqdm

    longest = int(np.max(np.diff([*np.asarray(train["block_starts"]), len(train["time"])])))
    if config.sequence_length > longest:
        raise HydrotactError(
            f"sequence-length {config.sequence_length}: longer than the longest training recording ({longest} samples), so every sequence would be "
            f"mostly padding; use at most {longest}"
        )
    inputs, targets = make_sequences(train, channels, normaliser, config.sequence_length, config.burn_in, targets=spec.targets)
    valid_inputs, valid_targets = make_sequences(held_out, channels, normaliser, config.sequence_length, config.burn_in, targets=spec.targets)
    if not len(inputs) or not len(valid_inputs):
        raise HydrotactError("training needs samples in both the training and the validation recordings")
    valid_inputs, valid_targets = jnp.asarray(valid_inputs), {k: jnp.asarray(v) for k, v in valid_targets.items()}
    batch = min(config.batch_size, len(inputs))
    steps_per_epoch = len(inputs) // batch
    optimiser = _make_optimiser(config, steps_per_epoch)
    step, evaluate = _make_functions(spec, optimiser, dict(config.weights))

    state = optimiser.init(params)
    best, best_loss, best_epoch, history, epoch = params, np.inf, -1, [], 0
    path = None if folder is None else Path(folder) / CHECKPOINT
    if path is not None and not path.is_file() and (path.parent / "model.json").is_file():
        raise HydrotactError(f"{path.parent}: holds a trained model without its checkpoint; train into another folder (nothing was changed)")
    if path is not None and path.is_file():
        stored = _load_checkpoint(path, request)
        count = len(jax.tree_util.tree_leaves(params))
        params = _unflat(params, [stored[f"params_{k}"] for k in range(count)])
        best = _unflat(best, [stored[f"best_{k}"] for k in range(count)])
        state = _unflat(state, [stored[f"state_{k}"] for k in range(len(jax.tree_util.tree_leaves(state)))])
        history = json.loads(str(stored["history"]))
        epoch, best_loss, best_epoch = len(history), float(stored["best_loss"]), int(stored["best_epoch"])

    stopped = "max_epochs"
    with tqdm(total=config.max_epochs * steps_per_epoch, initial=epoch * steps_per_epoch, unit="batch", desc=f"training {spec.architecture} {spec.hidden}", disable=not progress) as bar:
        while epoch < config.max_epochs:
            if epoch - best_epoch > config.patience and best_epoch >= 0:
                stopped = "early_stop"
                break
            started = time.perf_counter()
            order = np.random.default_rng([config.seed, epoch]).permutation(len(inputs))
            totals = []
            for b in range(steps_per_epoch):
                chosen = order[b * batch : (b + 1) * batch]
                params, state, value, terms = step(params, state, jnp.asarray(inputs[chosen]), {k: jnp.asarray(v[chosen]) for k, v in targets.items()})
                totals.append(float(value))
                bar.update(1)
            value, terms, metrics = evaluate(params, valid_inputs, valid_targets)
            entry = {
                "epoch": epoch, "train_loss": float(np.mean(totals)), "validation_loss": float(value),
                "validation_terms": {k: float(v) for k, v in terms.items()}, "validation_metrics": {k: float(v) for k, v in metrics.items()},
                "seconds": time.perf_counter() - started,
            }
            history.append(entry)
            if np.isfinite(entry["validation_loss"]) and entry["validation_loss"] < best_loss:
                best, best_loss, best_epoch = params, entry["validation_loss"], epoch
            bar.set_postfix_str(f"validation {entry['validation_loss']:.4g} (best {best_loss:.4g} at {best_epoch})")
            epoch += 1
            if path is not None:
                arrays = {f"params_{k}": leaf for k, leaf in enumerate(_flat(params))}
                arrays |= {f"best_{k}": leaf for k, leaf in enumerate(_flat(best))}
                arrays |= {f"state_{k}": leaf for k, leaf in enumerate(_flat(state))}
                with atomic_path(path, suffix=".npz") as tmp:
                    np.savez(tmp, request=np.asarray(request), history=np.asarray(json.dumps(history)), best_loss=best_loss, best_epoch=best_epoch, **arrays)
            if on_epoch is not None:
                on_epoch(entry)
    kept = best if config.restore_best else params
    return TrainedEstimator(spec, kept, normaliser, channels, config, history, best_epoch, stopped)
