"""Named choices: a string enum whose unknown values get one clear error."""

from enum import StrEnum

from ._errors import HydrotactError


class Choice(StrEnum):
    """A closed set of named options (a `StrEnum`: members compare equal to their
    names, so they read and write as plain strings in JSON and on the command line)."""

    @classmethod
    def parse(cls, value, what: str):
        """The member named `value` (a member passes through); otherwise a
        HydrotactError, "unknown WHAT 'value'; use one of ...", naming the choices."""
        try:
            return cls(value)
        except ValueError:
            choices = ", ".join(member.value for member in cls)
            raise HydrotactError(f"unknown {what} {value!r}; use one of {choices}") from None


BOARD_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
"""The sides of a mould's cavity, one of which lies on the sensor's board (`hydrotact
mesh --mould --board`): `ymax` is the cavity's side towards the mould's +y."""
