"""A dataset on disk: time-contiguous Parquet shards, the manifest, the run state of an
unfinished run, and reading it all back (host).

Layout of a dataset folder:

- `shard-00000.parquet`, ...: the session's rows in time order, `shard_rows` each;
- `manifest.json` (`data_schemas/dataset_manifest.schema.json`), written last: its
  presence means the dataset is complete;
- `.partial/`: the state of an unfinished run (`state.json`: the request's digest;
  `batch-NNNNN.npz`: the unit responses of each finished batch), removed at the end;
- the generator's plots (`*.png`).

Every file is written atomically. A folder with anything else in it, another
dataset, another run's state or a manifest that does not read is refused, and
nothing in it is touched.
"""

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np

from .._errors import HydrotactError
from .._files import atomic_path, write_text_atomic

MANIFEST = "manifest.json"
PARTIAL = ".partial"
SHARD_PATTERN = "shard-{:05d}.parquet"
PLOTS = ("coverage.png", "histograms.png", "channel_swing.png", "examples.png")
"""The plots `hydrotact generate` writes beside the shards."""


def sha256_file(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _is_ours(name: str) -> bool:
    return name in (MANIFEST, PARTIAL, *PLOTS) or (name.startswith("shard-") and name.endswith(".parquet")) or (name.startswith(".shard-") and ".parquet" in name)


def read_manifest(folder) -> dict:
    """The checked manifest of a dataset folder (one clear error if it is not one)."""
    from .._schemas import read_json, validate

    path = Path(folder) / MANIFEST
    if not path.is_file():
        raise HydrotactError(f"{folder}: no {MANIFEST}: not a hydrotact dataset (or its generation has not finished: run the same command again)")
    document = read_json(path)
    validate(document, "dataset_manifest", str(path))
    _check_rows(document, path)
    return document


def _check_rows(document: dict, path) -> None:
    """The shards laid end to end make the dataset's rows, and the split's ranges lie
    within them: one error naming the field of a manifest that says otherwise (edited,
    or another dataset's), before anything trains on it."""
    total, expected = int(document["num_rows"]), 0
    for k, shard in enumerate(document["shards"]):
        if shard["first_row"] != expected:
            raise HydrotactError(
                f"{path}: shards[{k}].first_row is {shard['first_row']}, but the shards before it end at row {expected}: the manifest does not match its shards; regenerate the dataset"
            )
        expected += shard["rows"]
    if expected != total:
        raise HydrotactError(f"{path}: num_rows is {total}, but the shards hold {expected} rows: the manifest does not match its shards; regenerate the dataset")
    for name in ("train", "test"):
        for k, (first, end) in enumerate(document["split"][name]):
            if not 0 <= first < end <= total:
                raise HydrotactError(f"{path}: split.{name}[{k}]: rows [{first}, {end}) do not lie within the dataset's {total} rows; regenerate the dataset")


def prepare_folder(folder, digest: str) -> str:
    """Check the output folder before any work: "new" (absent or empty), "resume" (an
    unfinished run of this same request) or "complete" (this same dataset, already
    written). Anything else is refused with one message naming what is there."""
    from .._files import check_output

    folder = check_output(folder, directory=True, what="the dataset")
    if not folder.exists() or not any(folder.iterdir()):
        return "new"
    foreign = sorted(entry.name for entry in folder.iterdir() if not _is_ours(entry.name))
    if foreign:
        listed = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise HydrotactError(f"{folder}: holds files that are not part of a hydrotact dataset ({listed}); nothing written: choose an empty or new folder")
    if (folder / MANIFEST).exists():
        try:
            manifest = read_manifest(folder)
        except HydrotactError as error:
            raise HydrotactError(f"{error}; the folder's manifest does not read, so it is left as it is: choose another folder, or remove it") from None
        if manifest["request_digest"] != digest:
            raise HydrotactError(
                f"{folder}: holds another dataset ({manifest['sensor']['name']}, {manifest['num_events']} events, seed {manifest['config']['seed']}); "
                "nothing written: choose another folder"
            )
        return "complete"
    state = folder / PARTIAL / "state.json"
    try:
        saved = json.loads(state.read_text())["request_digest"]
    except (OSError, ValueError, KeyError, TypeError):
        raise HydrotactError(f"{folder}: holds dataset files but neither a manifest nor the state of an unfinished run; nothing written: choose another folder") from None
    if saved != digest:
        raise HydrotactError(f"{folder}: holds an unfinished run of another dataset (other settings or inputs); run that command again to finish it, or choose another folder")
    return "resume"


def start_state(folder, digest: str, request: dict) -> Path:
    """Create the run-state folder (`.partial/`) of a new run; returns it."""
    partial = Path(folder) / PARTIAL
    partial.mkdir(parents=True, exist_ok=True)
    state = partial / "state.json"
    if not state.exists():
        write_text_atomic(state, json.dumps({"request_digest": digest, "request": request}, indent=2) + "\n")
    return partial


def finish_state(folder) -> None:
    shutil.rmtree(Path(folder) / PARTIAL, ignore_errors=True)


def write_shards(folder, table, shard_rows: int, on_shard=None) -> list[dict]:
    """Write a pyarrow Table as time-contiguous shards (atomically, each
    byte-identical for identical rows); their manifest entries."""
    import pyarrow.parquet as pq

    folder = Path(folder)
    entries = []
    count = (table.num_rows + shard_rows - 1) // shard_rows
    for number in range(count):
        first = number * shard_rows
        piece = table.slice(first, min(shard_rows, table.num_rows - first))
        path = folder / SHARD_PATTERN.format(number)
        with atomic_path(path, suffix=".parquet") as tmp:
            pq.write_table(piece, tmp, compression="zstd", write_statistics=False, store_schema=True)
        times = piece.column("time")
        entries.append({
            "file": path.name, "rows": int(piece.num_rows), "first_row": int(first),
            "time_range_s": [float(times[0].as_py()), float(times[-1].as_py())], "sha256": sha256_file(path),
        })
        if on_shard is not None:
            on_shard()
    return entries


def write_manifest(folder, manifest: dict) -> Path:
    from .._schemas import validate

    path = Path(folder) / MANIFEST
    validate(manifest, "dataset_manifest", str(path))
    write_text_atomic(path, json.dumps(manifest, indent=2) + "\n")
    return path


class Dataset:
    """A generated dataset, read back (host): `load_dataset(folder)`.

    **Attributes:** `manifest` (dict); `channels` (the barometer columns, the
    estimator's inputs); `labels` (the label columns); `columns` (all).

    **Methods:** `blocks(split)` the contiguous blocks of `split` ("train", "test" or
    "all") as dicts of arrays; `arrays(split)` those blocks concatenated (with
    `block_starts`); `windows(split, length, stride, columns)` fixed-length windows
    that never cross a block boundary. Shards are read memory-mapped through pyarrow;
    each shard's SHA-256 is checked against the manifest the first time it is read.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        self.manifest = read_manifest(self.folder)
        self.channels = list(self.manifest["channels"])
        self.columns = [column["name"] for column in self.manifest["columns"]]
        self.labels = [name for name in self.columns if name not in self.channels and name != "time"]
        self._table = None

    def __repr__(self) -> str:
        m = self.manifest
        return f"Dataset({str(self.folder)!r}: {m['sensor']['name']}, {m['num_events']} events, {m['num_rows']} rows at {m['config']['rate_hz']:g} Hz, {len(m['shards'])} shards)"

    @property
    def num_rows(self) -> int:
        return int(self.manifest["num_rows"])

    def table(self):
        """All rows as one pyarrow Table (memory-mapped shards, checked once)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        if self._table is None:
            pieces = []
            for entry in self.manifest["shards"]:
                path = self.folder / entry["file"]
                if not path.is_file():
                    raise HydrotactError(f"{path}: missing (the manifest lists it); the dataset is incomplete")
                if sha256_file(path) != entry["sha256"]:
                    raise HydrotactError(f"{path}: its SHA-256 differs from the manifest's: the shard was changed or damaged; generate the dataset again")
                piece = pq.read_table(path, memory_map=True)
                if piece.num_rows != entry["rows"]:
                    raise HydrotactError(f"{path}: {piece.num_rows} rows, the manifest says {entry['rows']}")
                pieces.append(piece)
            self._table = pa.concat_tables(pieces)
        return self._table

    def _ranges(self, split: str) -> list[tuple[int, int]]:
        if split == "all":
            return [(0, self.num_rows)]
        if split not in ("train", "test"):
            raise HydrotactError(f"split {split!r}: use 'train', 'test' or 'all'")
        return [tuple(pair) for pair in self.manifest["split"][split]]

    def blocks(self, split: str = "train", columns=None) -> list[dict]:
        table = self.table()
        names = self.columns if columns is None else list(columns)
        unknown = [name for name in names if name not in self.columns]
        if unknown:
            raise HydrotactError(f"{self.folder}: no column {unknown[0]!r} (has {', '.join(self.columns)})")
        return [{name: table.column(name).slice(start, stop - start).to_numpy() for name in names} for start, stop in self._ranges(split)]

    def arrays(self, split: str = "train", columns=None) -> dict:
        """The split's rows (its blocks one after the other) and `block_starts`."""
        blocks = self.blocks(split, columns)
        if not blocks:
            return {}
        result = {name: np.concatenate([block[name] for block in blocks]) for name in blocks[0]}
        result["block_starts"] = np.cumsum([0] + [len(next(iter(block.values()))) for block in blocks])[:-1]
        return result

    def windows(self, split: str = "train", length: int = 512, stride: int | None = None, columns=None):
        """Yield dicts of (length, ...) arrays: consecutive windows `stride` apart
        (default `length`), within one block each."""
        stride = stride or length
        if length < 1 or stride < 1:
            raise HydrotactError(f"windows: length and stride must be positive, got {length}, {stride}")
        for block in self.blocks(split, columns):
            size = len(next(iter(block.values())))
            for start in range(0, size - length + 1, stride):
                yield {name: values[start : start + length] for name, values in block.items()}


def load_dataset(folder) -> Dataset:
    """Open a generated dataset folder (checks its manifest; shards are read lazily,
    memory-mapped, and checked against their SHA-256 when first read)."""
    return Dataset(folder)
