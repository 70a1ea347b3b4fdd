"""Material documents: a viscoelastic elastomer as a Prony series, with uncertainties.

E(t) = E_inf + sum_i E_i exp(-t / tau_i): the long-term modulus E_inf, the relaxing
terms (E_i, tau_i) and the instantaneous modulus E_0 = E_inf + sum_i E_i, in Pa and s.
The contract is `data_schemas/material.schema.json`; reading also checks what the
schema cannot say (distinct taus, E_0 agreeing with the terms, a square symmetric
covariance), each as one line naming the file and the field.
"""

import datetime
import json
from pathlib import Path

import numpy as np

from .._errors import HydrotactError
from .._files import write_text_atomic
from .._schemas import read_json, validate

# E_0 given in a document must equal E_inf + sum E_i to this relative tolerance.
INSTANTANEOUS_TOLERANCE = 1e-9


def _quantity(value, std=None) -> dict:
    quantity = {"value": float(value)}
    if std is not None:
        quantity["std"] = float(std)
    return quantity


def _as_quantity(entry) -> dict:
    """A number, a (value, std) pair or a {value, std} dict as a quantity dict."""
    if isinstance(entry, dict):  # a std of None: none known
        return {key: float(value) for key, value in entry.items() if value is not None}
    if isinstance(entry, tuple | list):
        return _quantity(*entry)
    return _quantity(entry)


def parameter_names(num_terms: int) -> list[str]:
    """The default covariance parameter names for `num_terms` Prony terms:
    log_long_term_modulus, log_modulus_1..n, log_tau_1..n."""
    return ["log_long_term_modulus", *(f"log_modulus_{i}" for i in range(1, num_terms + 1)), *(f"log_tau_{i}" for i in range(1, num_terms + 1))]


def make_material_document(
    long_term_modulus: float,
    moduli,
    taus,
    *,
    stds: dict | None = None,
    covariance=None,
    channels=None,
    provenance: dict | None = None,
    name: str | None = None,
    description: str | None = None,
) -> dict:
    """A material document from numbers (checked against the schema and its invariants).

    **Arguments:**

    - `long_term_modulus`: E_inf, Pa.
    - `moduli`, `taus`: (num_terms,) E_i in Pa and tau_i in s.
    - `stds`: standard deviations, {"long_term_modulus": s, "moduli": [...], "taus": [...]}
      (any subset).
    - `covariance`: a (P, P) matrix over :func:`parameter_names` in log space, or a
      schema `covariance` dict {parameters, space, matrix}.
    - `channels`: [{"name", "gain", "offset_Pa"}, ...]; gain and offset a number, a
      (value, std) pair or a {value, std} dict.
    - `provenance`: fields over the defaults {generator: "hydrotact VERSION", created:
      now (UTC), method: "manual"}.
    - `name`, `description`: free text.

    **Returns:** the document (a dict), with E_0 = E_inf + sum E_i filled in.
    """
    from .. import __version__

    stds = stds or {}
    moduli = [float(value) for value in np.atleast_1d(np.asarray(moduli, dtype=np.float64))]
    taus = [float(value) for value in np.atleast_1d(np.asarray(taus, dtype=np.float64))]
    if len(moduli) != len(taus):
        raise HydrotactError(f"material: {len(moduli)} moduli but {len(taus)} taus")
    modulus_stds = list(stds.get("moduli", [None] * len(moduli)))
    tau_stds = list(stds.get("taus", [None] * len(taus)))
    document = {"format": "hydrotact.material", "version": 1}
    if name is not None:
        document["name"] = name
    if description is not None:
        document["description"] = description
    document["long_term_modulus_Pa"] = _quantity(long_term_modulus, stds.get("long_term_modulus"))
    document["prony_terms"] = [
        {"modulus_Pa": _quantity(modulus, modulus_std), "tau_s": _quantity(tau, tau_std)}
        for modulus, tau, modulus_std, tau_std in zip(moduli, taus, modulus_stds, tau_stds, strict=True)
    ]
    document["instantaneous_modulus_Pa"] = _quantity(float(long_term_modulus) + sum(moduli))
    if covariance is not None:
        if isinstance(covariance, dict):
            document["covariance"] = covariance
        else:
            matrix = np.asarray(covariance, dtype=np.float64)
            document["covariance"] = {"parameters": parameter_names(len(moduli)), "space": "log", "matrix": matrix.tolist()}
    if channels is not None:
        document["channels"] = [
            {key: (value if key == "name" else _as_quantity(value)) for key, value in channel.items()} for channel in channels
        ]
    created = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    document["provenance"] = {"generator": f"hydrotact {__version__}", "created": created, "method": "manual", **(provenance or {})}
    check_material(document)
    return document


def check_material(document, source: str = "material document") -> None:
    """Validate a material document: the schema, then distinct taus, E_0 = E_inf +
    sum E_i (1e-9 relative) when given, a square symmetric covariance with side
    len(parameters) and variances >= 0, distinct channel names. One
    :class:`HydrotactError` naming `source` and the field."""
    validate(document, "material", source)
    terms = document["prony_terms"]
    for index, term in enumerate(terms):
        tau = term["tau_s"]["value"]
        for earlier in range(index):
            if terms[earlier]["tau_s"]["value"] == tau:
                raise HydrotactError(f"{source}: prony_terms[{index}].tau_s.value: {tau:g} s is also prony_terms[{earlier}]'s; the taus must be distinct")
    if "instantaneous_modulus_Pa" in document:
        given = document["instantaneous_modulus_Pa"]["value"]
        expected = document["long_term_modulus_Pa"]["value"] + sum(term["modulus_Pa"]["value"] for term in terms)
        if abs(given - expected) > INSTANTANEOUS_TOLERANCE * expected:
            raise HydrotactError(
                f"{source}: instantaneous_modulus_Pa.value: {given:.12g} Pa is not long_term_modulus_Pa + the prony_terms' moduli ({expected:.12g} Pa)"
            )
    if "covariance" in document:
        _check_covariance(document["covariance"], source)
    names = [channel["name"] for channel in document.get("channels", [])]
    for index, name in enumerate(names):
        if name in names[:index]:
            raise HydrotactError(f"{source}: channels[{index}].name: {name!r} is listed twice")


def _check_covariance(covariance: dict, source: str) -> None:
    side = len(covariance["parameters"])
    rows = covariance["matrix"]
    if len(rows) != side:
        raise HydrotactError(f"{source}: covariance.matrix: {len(rows)} rows for {side} parameters")
    for index, row in enumerate(rows):
        if len(row) != side:
            raise HydrotactError(f"{source}: covariance.matrix[{index}]: {len(row)} numbers, expected {side} (one per parameter)")
    matrix = np.asarray(rows, dtype=np.float64)
    for index in range(side):
        if matrix[index, index] < 0.0:
            raise HydrotactError(f"{source}: covariance.matrix[{index}][{index}]: a variance must be >= 0, got {matrix[index, index]:g}")
    scale = max(float(np.max(np.abs(matrix))), np.finfo(np.float64).tiny)
    asymmetric = np.abs(matrix - matrix.T) > 1e-9 * scale
    if asymmetric.any():
        row, column = (int(k) for k in np.argwhere(asymmetric)[0])
        raise HydrotactError(f"{source}: covariance.matrix[{row}][{column}]: {matrix[row, column]:g} differs from [{column}][{row}] {matrix[column, row]:g}; a covariance is symmetric")


def write_material(path, document: dict) -> Path:
    """Check a material document and write it as JSON, atomically.

    **Arguments:** `path`: the JSON file; `document`: the material document.

    **Returns:** `path`.
    """
    path = Path(path)
    check_material(document, str(path))
    write_text_atomic(path, json.dumps(document, indent=2) + "\n")
    return path


def read_material(path) -> dict:
    """Read and check a material document (:func:`check_material`).

    **Arguments:** `path`: the JSON file.

    **Returns:** the document (a dict; SI units).
    """
    document = read_json(path)
    check_material(document, str(path))
    return document


def material_prony(document: dict, source: str = "material document"):
    """The Prony series (hydrotact.visco.Prony) of a checked material document; a
    relative-scale (lumped-fit) material cannot drive a simulation."""
    from ..visco import make_prony

    if document.get("modulus_scale") == "relative":
        raise HydrotactError(f"{source}: modulus_scale: a relative material (from a lumped fit) has no moduli in Pa; it cannot drive a simulation")
    terms = document["prony_terms"]
    return make_prony(document["long_term_modulus_Pa"]["value"], [t["modulus_Pa"]["value"] for t in terms], [t["tau_s"]["value"] for t in terms], source=source)
