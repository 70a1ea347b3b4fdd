"""What a fit leaves behind: `material.json`, `report.json` and plots.

- `material.json` (data_schemas/material.schema.json): E∞ and the Prony terms with
  standard errors, their covariance (log space), the fitted channel gains and
  offsets, and provenance (logs with SHA-256, solver, mode, criterion).
- `report.json`: every parameter ± standard error, the fit's statistics, residual
  diagnostics per channel, and the criterion per number of terms when it was chosen.
- plots, drawn by the caller's `plot` (`hydrotact.viz.plot_fit`: traces, residuals,
  and E(t) with the 95 % band of `calc_relaxation_band`).
"""

import json
from pathlib import Path

import numpy as np

from .. import __version__
from .._files import atomic_path, write_text_atomic
from ..data import make_material_document, write_material
from ._fit import FitResult


def _material_order(result: FitResult) -> list[int]:
    """Indices into x of [E∞, E₁..E_K, τ₁..τ_K] with terms sorted by τ."""
    names = result.names
    taus = [result.x[names.index(f"log_tau_{k + 1}")] for k in range(result.layout.num_terms)]
    order = np.argsort(taus)
    return [names.index("log_long_term_modulus")] + [names.index(f"log_modulus_{k + 1}") for k in order] + [names.index(f"log_tau_{k + 1}") for k in order]


def _finite(std):
    return float(std) if np.isfinite(std) else None


def make_fit_material(result: FitResult, paths=(), name: str | None = None) -> dict:
    """The material document of a fit (schema-checked)."""
    terms = result.terms
    index = _material_order(result)
    covariance = result.covariance[np.ix_(index, index)]
    count = result.layout.num_terms
    parameters = ["log_long_term_modulus"] + [f"log_modulus_{k + 1}" for k in range(count)] + [f"log_tau_{k + 1}" for k in range(count)]
    channels = []
    gains = result.gains
    for info, offsets in zip(result.problem.infos, result.offsets()):
        if len(result.problem.infos) > 1:
            break  # offsets are per log; with several logs they stay in the report
        for channel in info.channels:
            entry = {"name": channel, "offset_Pa": offsets[channel].to_json()}
            gain = gains.get(f"{info.sensor}/{channel}")
            if gain is not None:
                entry["gain"] = gain.to_json()
            channels.append(entry)
    sensors = sorted({info.sensor for info in result.problem.infos if info.sensor})
    provenance = {
        "method": "fit",
        "mode": "full",
        "solver": result.solver_name,
        "logs": [{"path": str(path), **({"sha256": info.sha256} if info.sha256 else {})} for path, info in zip(paths or [i.source for i in result.problem.infos], result.problem.infos)],
        "num_samples": int(sum(int(log.times.shape[0]) for log in result.problem.logs)),
        "cost": 0.5 * result.chi_square,
    }
    if len(sensors) == 1:
        provenance["sensor"] = sensors[0]
    if result.criteria:
        provenance["criterion"] = {"name": "bic", "value": result.bic}
    document = make_material_document(
        result.long_term_modulus.value,
        [m.value for m, _ in terms],
        [t.value for _, t in terms],
        stds={"long_term_modulus": _finite(result.long_term_modulus.std), "moduli": [_finite(m.std) for m, _ in terms], "taus": [_finite(t.std) for _, t in terms]},
        # A covariance with entries that are not finite (a direction the logs do not
        # constrain) is left out, with those standard errors: the report says which.
        covariance={"parameters": parameters, "space": "log", "matrix": covariance.tolist()} if np.all(np.isfinite(covariance)) else None,
        channels=channels or None,
        provenance=provenance,
        name=name,
        description=f"Fitted by hydrotact {__version__} (full mode, {count} Prony terms, solver {result.solver_name}).",
    )
    return document


def _identified(estimate, verdict) -> dict:
    ok, note = verdict
    return {**estimate.to_json(), "identified": ok, **({"note": note} if note else {})}


def make_report(result: FitResult) -> dict:
    """The fit's numbers as a JSON-ready dict."""
    report = {
        "generator": f"hydrotact {__version__}",
        "mode": "full",
        "solver": result.solver_name,
        "num_terms": result.layout.num_terms,
        "converged": result.converged,
        "num_steps": result.num_steps,
        "seconds": result.seconds,
        "num_residuals": result.num_residuals,
        "num_parameters": result.layout.size,
        "chi_square": result.chi_square,
        "reduced_chi_square": result.reduced_chi_square,
        "bic": result.bic,
        "long_term_modulus_Pa": result.long_term_modulus.to_json(),
        "instantaneous_modulus_Pa": result.instantaneous_modulus.to_json(),
        "prony_terms": [
            {"modulus_Pa": _identified(m, m_ok), "tau_s": _identified(t, t_ok)} for (m, t), (m_ok, t_ok) in zip(result.terms, result.identification())
        ],
        "gains": {name: estimate.to_json() for name, estimate in result.gains.items()},
        "gains_relative": bool(result.layout.relative_gains),
        "gains_outside_the_mean": result.gains_outside_the_mean(),
        "offsets_Pa": [{"source": info.source, "channels": {k: v.to_json() for k, v in offsets.items()}} for info, offsets in zip(result.problem.infos, result.offsets())],
        "residuals": result.residual_diagnostics(),
    }
    if result.problem.rig is not None:
        verdicts = result.rig_identification()
        report["rig"] = {
            name: {**_identified(estimate, verdicts.get(name, (True, ""))), "fitted": name in verdicts}
            for name, estimate in result.rig_parameters().items()
        }
        report["drift_columns"] = list(result.layout.drifts)
        report["rig_setup"] = result.problem.rig.setup_document()
        report["logs"] = [{"source": info.source, "sha256": info.sha256, "sensor": info.sensor} for info in result.problem.infos]
    if result.criteria:
        report["criterion"] = {"name": "bic", "by_num_terms": {str(k): v for k, v in result.criteria.items()}}
    return report


def calc_relaxation_band(result: FitResult, times, draws: int = 400, seed: int = 0):
    """E(t) at `times` and its 2.5 / 97.5 % band from draws of the material's
    log-space covariance (NumPy)."""
    index = _material_order(result)
    mean = result.x[index]
    covariance = result.covariance[np.ix_(index, index)]
    rng = np.random.default_rng(seed)
    samples = rng.multivariate_normal(mean, covariance, size=draws, method="eigh")
    count = result.layout.num_terms

    def moduli(x):  # E(t) for rows of log parameters x (NumPy, all draws at once)
        x = np.atleast_2d(x)
        terms = np.exp(x[:, 1 : 1 + count])[:, None, :] * np.exp(-times[None, :, None] / np.exp(x[:, 1 + count :])[:, None, :])
        return np.exp(x[:, 0])[:, None] + terms.sum(axis=-1)

    # a fit far from its data has a vast covariance: its band is then unbounded (a draw
    # of τ that underflows to 0 decays at once), not an error
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        curves = moduli(samples)
        return moduli(mean)[0], np.percentile(curves, 2.5, axis=0), np.percentile(curves, 97.5, axis=0)


def write_fit_outputs(result: FitResult, out_dir, paths=(), plot=None) -> dict:
    """material.json, report.json and, with `plot`, the plots in out_dir (each written
    atomically).

    `plot(result, out_dir) -> {name: path}` draws the pictures: pass
    `hydrotact.viz.plot_fit` for traces.png, residuals.png and relaxation.png. The
    stage draws nothing itself (no stage imports `hydrotact.viz`). Returns the report,
    with `files` naming everything written."""
    files = {}
    if result.problem.rig is not None:  # what `compare` reads the held-out logs' responses off
        table = result.problem.rig.table
        files["rig_table"] = str(Path(out_dir) / "rig_table.npz")
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        with atomic_path(files["rig_table"]) as tmp:
            np.savez(tmp, origin=np.asarray(table.origin), step=np.asarray(table.step), values=np.asarray(table.values))
    return write_outputs(result, out_dir, make_fit_material(result, paths), make_report(result), plot, files=files)


def write_outputs(result, out_dir, material: dict, report: dict, plot=None, files=None) -> dict:
    """Write a fit's `material` document and, with `plot(result, out_dir) -> {name:
    path}`, its pictures into out_dir, then `report` with `files` naming everything
    written (report.json last, each file atomically; `files` those the caller wrote
    before). Returns the report."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {**(files or {}), "material": str(out_dir / "material.json"), "report": str(out_dir / "report.json")}
    write_material(files["material"], material)
    if plot is not None:
        files.update(plot(result, out_dir))
    report["files"] = files
    write_text_atomic(files["report"], json.dumps(report, indent=2) + "\n")
    return report
