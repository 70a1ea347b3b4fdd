"""A trained estimator on disk: `model.json` (what it is: the estimator's spec, the
input channels and their normalisation, the training settings and history, the
sensor) and `weights.npz` (the parameters, float32), each written atomically."""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._files import atomic_path, write_text_atomic
from .._schemas import validate
from ._estimator import EstimatorSpec, init_estimator
from ._sequences import Normaliser
from ._train import TrainConfig, TrainedEstimator

MODEL = "model.json"
WEIGHTS = "weights.npz"
FORMAT = "hydrotact.estimator"


def save_estimator(trained: TrainedEstimator, folder, sensor_name: str) -> Path:
    """Write `trained` into `folder` (created if needed); returns the model.json path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    leaves = [np.asarray(leaf, dtype=np.float32) for leaf in jax.tree_util.tree_leaves(trained.params)]
    with atomic_path(folder / WEIGHTS, suffix=".npz") as tmp:
        np.savez(tmp, **{f"w{k}": leaf for k, leaf in enumerate(leaves)})
    document = {
        "format": FORMAT, "version": 1, "sensor": sensor_name, "spec": trained.spec.to_json(), "channels": list(trained.channels),
        "normaliser": trained.normaliser.to_json(), "config": trained.config.to_json(), "best_epoch": trained.best_epoch,
        "stopped": trained.stopped, "history": trained.history,
    }
    write_text_atomic(folder / MODEL, json.dumps(document, indent=2) + "\n")
    return folder / MODEL


def load_estimator(folder) -> TrainedEstimator:
    """Read a model folder written by :func:`save_estimator`."""
    folder = Path(folder)
    path = folder / MODEL
    try:
        document = json.loads(path.read_text())
    except FileNotFoundError:
        raise HydrotactError(f"{path}: no such file (a model folder holds model.json and weights.npz, from hydrotact train)") from None
    except json.JSONDecodeError as error:
        raise HydrotactError(f"{path}: not JSON ({error.msg}, line {error.lineno})") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise HydrotactError(f"{path}: not a hydrotact estimator (format {document.get('format') if isinstance(document, dict) else None!r})")
    if not isinstance(document.get("history"), list):
        raise HydrotactError(f"{path}: history: must be a list of epochs")
    validate(document | {"history": []}, "model", str(path))  # the history's metrics may be NaN (over no sample)
    sizes = {"spec.num_inputs": document["spec"]["num_inputs"], "channels": len(document["channels"]), "normaliser.mean_Pa": len(document["normaliser"]["mean_Pa"]),
             "normaliser.std_Pa": len(document["normaliser"]["std_Pa"]), **({"normaliser.rest_Pa": len(document["normaliser"]["rest_Pa"])} if "rest_Pa" in document["normaliser"] else {})}
    if len(set(sizes.values())) > 1:
        found = ", ".join(f"{key} {value}" for key, value in sizes.items())
        raise HydrotactError(f"{path}: the model's inputs disagree: {found} (one per channel read); the file was edited or damaged: retrain")
    targets = document["spec"].get("targets", [])
    for key in ("target_offsets", "target_scales"):
        if key in document["spec"] and len(document["spec"][key]) != len(targets):
            raise HydrotactError(f"{path}: spec.{key}: {len(document['spec'][key])} values for {len(targets)} targets")
    if not 0 <= document["best_epoch"] < max(1, len(document["history"])):
        raise HydrotactError(f"{path}: best_epoch: {document['best_epoch']}, but the history holds {len(document['history'])} epochs")
    spec = EstimatorSpec.from_json(document["spec"])
    like = init_estimator(spec, jax.random.PRNGKey(0))
    try:
        with np.load(folder / WEIGHTS, allow_pickle=False) as saved:
            leaves = [saved[f"w{k}"] for k in range(len(jax.tree_util.tree_leaves(like)))]
    except (OSError, KeyError, ValueError) as error:
        raise HydrotactError(f"{folder / WEIGHTS}: unreadable or not this model's weights ({error})") from None
    for k, (leaf, expected) in enumerate(zip(leaves, jax.tree_util.tree_leaves(like))):
        if leaf.shape != expected.shape:
            raise HydrotactError(f"{folder / WEIGHTS}: a weight of shape {leaf.shape}, the model needs {expected.shape}")
        if not np.all(np.isfinite(leaf)):
            raise HydrotactError(f"{folder / WEIGHTS}: w{k} holds {int(np.sum(~np.isfinite(leaf)))} values that are not finite (NaN or inf): a diverged or damaged training; retrain")
    params = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(like), [jnp.asarray(leaf) for leaf in leaves])
    normaliser = Normaliser.from_json(document["normaliser"])
    config = dict(document["config"])
    config["hidden"] = None if config["hidden"] is None else tuple(config["hidden"])
    config["weights"] = tuple(config["weights"].items())
    if "targets" in config:
        config["targets"] = tuple(config["targets"])
    return TrainedEstimator(spec, params, normaliser, tuple(document["channels"]), TrainConfig(**config), document["history"], int(document["best_epoch"]), document["stopped"])
