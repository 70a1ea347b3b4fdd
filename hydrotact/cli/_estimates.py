"""What evaluate and predict share: a model's recordings from datasets and logs."""

def recordings(model, sources, split: str):
    """(name, blocks, rate) per source: a dataset folder's split, or a log file (one block)."""
    from .._errors import HydrotactError
    from ..data import read_log
    from ..datasets import load_dataset

    for source in sources:
        if source.is_dir():
            dataset = load_dataset(source)
            if list(dataset.channels) != list(model.channels):
                raise HydrotactError(f"{source}: channels {', '.join(dataset.channels)}, the model reads {', '.join(model.channels)}")
            yield str(source), dataset.blocks(split), float(dataset.manifest["config"]["rate_hz"])
        else:
            log = read_log(source)
            block = log_block(model, log, source)
            _check_labels(model, block, source)
            yield str(source), [block], 1.0 / float(max(1e-9, (log.times[-1] - log.times[0]) / max(1, log.num_samples - 1)))


def _check_labels(model, columns, source) -> None:
    """A log evaluated needs a label per target and the contact flag: one line naming
    the first missing (not a KeyError halfway through)."""
    from .._errors import HydrotactError
    from ..models import LABEL_COLUMNS

    for target in (*model.spec.targets, "contact"):
        names = LABEL_COLUMNS.get(target, (target,))
        if not any(name in columns for name in names):
            raise HydrotactError(f"{source}: no label for the estimator's {target!r} (a column {' or '.join(repr(n) for n in names)}): evaluate scores the estimates "
                                 "against a log's labels; hydrotact predict estimates without them")


def log_block(model, log, source) -> dict:
    from .._errors import HydrotactError

    if log.metadata.get("pressure") != "absolute":
        raise HydrotactError(f"{source}: pressure: the channels hold {log.metadata.get('pressure')!r} pressures; the model reads absolute barometer readings (simulate with --barometer)")
    missing = [name for name in model.channels if name not in log.columns]
    if missing:
        raise HydrotactError(f"{source}: no channel {missing[0]!r}; the model reads {', '.join(model.channels)}")
    return log.columns
