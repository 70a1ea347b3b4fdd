"""JSON documents and their schemas: read, validate, and say in one line what is wrong.

The schemas live in `data_schemas/` (the one canonical copy); the installed package
reaches them as `hydrotact._schema_files` (a link to that folder, which setuptools
ships as package data). Every reader of a JSON file goes through :func:`read_json` and
:func:`validate`, so a bad file always gets one :class:`HydrotactError` line naming the
file and the field, e.g. ``my_sensor.json: taxels[3].axis: must have 3 numbers, got 2``.
"""

import functools
import json
import math
from collections import defaultdict
from importlib.resources import files
from pathlib import Path

import jsonschema
import referencing
from jsonschema.exceptions import relevance

from ._errors import HydrotactError, where

_TYPE_WORDS = {
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "object": "an object",
    "array": "an array",
    "boolean": "true or false",
    "null": "null",
}


@functools.cache
def load_schema(name: str) -> dict:
    """The schema `data_schemas/{name}.schema.json` as a dict (e.g. name="sensor")."""
    resource = files("hydrotact._schema_files") / f"{name}.schema.json"
    if not resource.is_file():
        raise HydrotactError(f"no schema named {name!r}: hydrotact is installed without data_schemas/{name}.schema.json")
    return json.loads(resource.read_text(encoding="utf-8"))


@functools.cache
def _validator(name: str, definition: str | None) -> jsonschema.Draft202012Validator:
    schema = load_schema(name)
    uri = schema["$id"]
    registry = referencing.Registry().with_resource(uri, referencing.Resource.from_contents(schema))
    target = schema if definition is None else {"$ref": f"{uri}#/$defs/{definition}"}
    return jsonschema.Draft202012Validator(target, registry=registry)


def format_path(path) -> str:
    """A JSON path as `taxels[3].axis` ('(document)' for the root)."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or "(document)"


def read_json(path, source: str | None = None):
    """Parse the JSON file at `path`; a missing or malformed file is one clear error."""
    path = Path(path)
    source = source or str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise HydrotactError(f"{source}: no such file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise HydrotactError(f"{source}: cannot read ({error})") from None
    return parse_json(text, source)


def parse_json(text: str, source: str | None = None):
    """Parse JSON text; a syntax error names the line and column."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise HydrotactError(f"{where(source)}not valid JSON: {error.msg} (line {error.lineno}, column {error.colno})") from None


def check_finite(document, source: str | None = None, path=()) -> None:
    """Raise if any number in the document is NaN or infinite (JSON has no such numbers,
    but Python's json module reads them)."""
    if isinstance(document, float) and not math.isfinite(document):
        raise HydrotactError(f"{where(source)}{format_path(path)}: must be a finite number, got {document}")
    if isinstance(document, dict):
        for key, value in document.items():
            check_finite(value, source, (*path, key))
    elif isinstance(document, list):
        for index, value in enumerate(document):
            check_finite(value, source, (*path, index))


def validate(document, schema_name: str, source: str | None = None, definition: str | None = None) -> None:
    """Check `document` against the schema `schema_name` (or its `$defs/definition`).

    Raises one :class:`HydrotactError` line for the most relevant error,
    ``SOURCE: FIELD.PATH: what is wrong``.
    """
    check_finite(document, source)
    errors = list(_validator(schema_name, definition).iter_errors(document))
    if not errors:
        return
    error = _pick(max(errors, key=relevance))
    path, message = _describe(error)
    raise HydrotactError(f"{where(source)}{format_path(path)}: {message}")


def _is_discriminator(error) -> bool:
    """Whether `error` says the instance is not of this oneOf branch's kind at all."""
    path = list(error.relative_path)
    return (
        (error.validator == "type" and not path)
        or (error.validator == "const" and path == ["kind"])
        or (error.validator == "required" and not path and "kind" in error.validator_value and "kind" not in error.instance)
    )


def _pick(error):
    """The error to report: through oneOf/anyOf, the most specific error of the one
    branch the instance evidently meant (its `kind` or its type matches); jsonschema's
    own best_match may pick an error from a branch the instance never meant."""
    if error.validator not in ("oneOf", "anyOf") or not error.context:
        return error
    branches = defaultdict(list)
    for sub in error.context:
        branches[sub.relative_schema_path[0]].append(sub)
    viable = [errors for errors in branches.values() if not any(_is_discriminator(e) for e in errors)]
    if len(viable) != 1:
        return error
    return _pick(min(viable[0], key=relevance))


def _show(value) -> str:
    if isinstance(value, dict):
        return "an object"
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _describe(error) -> tuple[list, str]:
    """(path, message) for one jsonschema error, in our words."""
    path = list(error.absolute_path)
    kind, value, instance = error.validator, error.validator_value, error.instance
    if kind in ("oneOf", "anyOf"):
        kinds, types = [], []
        for sub in error.context:
            branch_kind = sub.schema.get("properties", {}).get("kind", {}).get("const") if isinstance(sub.schema, dict) else None
            if sub.validator == "const" and list(sub.relative_path) == ["kind"]:
                kinds.append(sub.validator_value)
            elif branch_kind is not None and not list(sub.relative_path):
                kinds.append(branch_kind)
            elif sub.validator == "type" and not list(sub.relative_path):
                types.append(sub.validator_value)
        kinds, types = list(dict.fromkeys(kinds)), list(dict.fromkeys(types))
        if isinstance(instance, dict) and "kind" not in instance and kinds:
            return [*path, "kind"], f"is missing (one of {', '.join(map(json.dumps, kinds))})"
        if isinstance(instance, dict) and kinds:
            return [*path, "kind"], f"must be one of {', '.join(map(json.dumps, kinds))}, got {_show(instance['kind'])}"
        if types:
            words = " or ".join(_TYPE_WORDS.get(t, t) for t in types)
            return path, f"must be {words}, got {_show(instance)}"
        return path, "matches none of the allowed forms" if error.context else "matches more than one allowed form"
    if kind == "type":
        types = value if isinstance(value, list) else [value]
        return path, f"must be {' or '.join(_TYPE_WORDS.get(t, t) for t in types)}, got {_show(instance)}"
    if kind == "required":
        missing = [name for name in value if name not in instance]
        return [*path, missing[0]], "is missing"
    if kind == "additionalProperties":
        allowed = sorted(error.schema.get("properties", {}))
        extra = sorted(set(instance) - set(allowed))
        return [*path, extra[0]], f"unknown field; allowed here: {', '.join(allowed)}"
    if kind == "minItems" and value == 1 and not instance:
        return path, "must not be empty"
    if kind in ("minItems", "maxItems"):
        items = error.schema.get("items", {})
        noun = {"number": "numbers", "string": "strings"}.get(items.get("type"), "items")
        low, high = error.schema.get("minItems"), error.schema.get("maxItems")
        count = f"{low}" if low == high else (f"at least {value}" if kind == "minItems" else f"at most {value}")
        return path, f"must have {count} {noun}, got {len(instance)}"
    if kind == "enum":
        return path, f"must be one of {', '.join(map(json.dumps, value))}, got {_show(instance)}"
    if kind == "const":
        return path, f"must be {json.dumps(value)}, got {_show(instance)}"
    comparisons = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">", "exclusiveMaximum": "<"}
    if kind in comparisons:
        return path, f"must be {comparisons[kind]} {value:g}, got {instance:g}"
    if kind == "minLength" and value == 1:
        return path, "must not be empty"
    if kind == "minProperties" and value == 1:
        return path, "must not be empty"
    return path, error.message.splitlines()[0]
