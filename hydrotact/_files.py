"""Atomic file writing and the on-disk cache."""

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path

from ._errors import HydrotactError


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside `path`; on success it replaces `path` at once.

    A reader never sees a half-written file, and an interrupted write leaves the old
    file (if any) untouched.
    """
    path = Path(path)
    if path.is_dir():
        raise HydrotactError(f"{path}: is a folder, not a file; name the file to write")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix or path.suffix)
    except OSError as error:  # a folder nobody may write in (/proc), a path under a file: name the output, not a temporary name
        raise HydrotactError(f"{path}: cannot write in {path.parent}/ ({error.strerror or error})") from None
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        try:
            os.replace(tmp, path)
        except OSError as error:
            raise HydrotactError(f"{path}: cannot be written ({error.strerror or error})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def check_output(path, *, directory: bool = False, suffixes: tuple[str, ...] = (), what: str = "") -> Path:
    """Refuse, before any work, an output that could not be written: a file whose path
    is a folder (or a folder that is a file), a path under a file, a folder nobody may
    write in, a name without one of `suffixes`. Writes nothing but a probe file that
    is removed at once (the only sure test of a folder, e.g. under /proc).

    **Arguments:**

    - `path`: the file (or, with `directory`, the folder) a job will write.
    - `suffixes`: the suffixes allowed (lower case, with the dot), or () for any.
    - `what`: what the file is (`the log`, `the plot`), for the message.

    **Returns:** `path` as a Path. **Raises:** :class:`HydrotactError` naming it.
    """
    path = Path(path)
    what = f"{what} " if what else ""
    if suffixes and path.suffix.lower() not in suffixes:
        names = " or ".join(f"*{suffix}" for suffix in suffixes)
        raise HydrotactError(f"{path}: {what}is written as {names}; name it so")
    if path.exists() and path.is_dir() != directory:
        kind = "a folder, not a file" if path.is_dir() else "a file, not a folder"
        raise HydrotactError(f"{path}: is {kind}; {what}needs {'a folder' if directory else 'a file name'} here")
    folder = path if directory else path.parent
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise HydrotactError(f"{path}: {existing} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as error:
        raise HydrotactError(f"{path}: cannot write in {existing}/ ({error.strerror or error})") from None
    return path


@contextlib.contextmanager
def removed_if_refused(folder):
    """Run a job that writes into `folder`: if the job is refused (a HydrotactError)
    and the folder was not there before it, the folder goes too, so a refused run
    leaves nothing behind; a folder that was there (a killed run's state to resume
    from, an earlier output) is kept."""
    import shutil

    existed = Path(folder).exists()
    try:
        yield
    except HydrotactError:
        if not existed:
            shutil.rmtree(folder, ignore_errors=True)
        raise


def write_text_atomic(path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def cache_dir() -> Path:
    """Where hydrotact caches meshes and (the command's) compiled XLA programs:
    $HYDROTACT_CACHE_DIR, else ~/.cache/hydrotact."""
    root = os.environ.get("HYDROTACT_CACHE_DIR")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hydrotact"


def digest(*parts) -> str:
    """A SHA-256 hex digest of bytes and reprs of the parts."""
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else repr(part).encode())
        h.update(b"\x00")
    return h.hexdigest()
