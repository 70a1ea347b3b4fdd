"""The one exception type users see.

Every problem with a user's input (a file, a mesh, a parameter) is raised as a
:class:`HydrotactError` whose message names the file, field or row at fault. The
command line prints that message on one line and exits with status 2; it never shows
a traceback for one.
"""

import warnings


class HydrotactError(ValueError):
    """A problem with the user's input, with a message that says where it is."""


class HydrotactWarning(UserWarning):
    """Input that is accepted but may mislead (a clipped reading, uneven sampling), with
    the figures. The command line prints it as one `hydrotact: warning: ...` line."""


def warn(message: str, category: type = HydrotactWarning) -> None:
    """Issue `message` as a :class:`HydrotactWarning` (or a subclass) through
    :mod:`warnings`, attributed to the caller's caller: the one way hydrotact warns."""
    warnings.warn(message, category, stacklevel=3)


def where(source: str | None) -> str:
    """Prefix for a message about `source` (a file name or a description), or ''."""
    return f"{source}: " if source else ""
