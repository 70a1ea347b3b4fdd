"""What a lumped press fit leaves behind: `material.json` (the relative Prony series
and the channel law that `compare` predicts with), `report.json` and plots."""


from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ... import __version__
from ..._files import atomic_path
from ...data import make_material_document
from ..shared import file_digest, write_outputs
from ._press_fit import PressFit
from ._press_windows import DEPTH_SCALE, POWERS, calc_depths

COVARIANCE_FILE = "channel_law_covariance.npz"  # beside material.json


def make_press_material(fit: PressFit, paths=(), name: str | None = None) -> dict:
    """The material document of a press fit (schema-checked): E∞ ≡ 1 (relative), the
    terms' Eᵢ/E∞ and τᵢ with standard errors, and `channel_law`."""
    provenance = {
        "method": "fit",
        "mode": "lumped",
        "solver": fit.solver,
        "logs": [{"path": str(path), **({"sha256": file_digest(path)} if file_digest(path) else {})} for path in paths],
        "num_samples": int(sum(int(log.mask.any(axis=1).sum()) for log in fit.logs)),
        "cost": 0.5 * fit.chi_square,
    }
    document = make_material_document(
        1.0,
        [r.value for r in fit.ratios],
        [t.value for t in fit.taus],
        stds={"moduli": [r.std for r in fit.ratios], "taus": [t.std for t in fit.taus]},
        provenance=provenance,
        name=name,
        description=f"Fitted by hydrotact {__version__} (lumped press model, {fit.num_terms} Prony terms, solver {fit.solver}): relative moduli E_i / E_inf.",
    )
    document["modulus_scale"] = "relative"
    document["channel_law"] = channel_law(fit)
    write_order = ["format", "version", "name", "description", "modulus_scale", "long_term_modulus_Pa", "prony_terms", "instantaneous_modulus_Pa", "channel_law", "provenance"]
    return {key: document[key] for key in write_order if key in document}


_depths = eqx.filter_jit(calc_depths)  # one compiled program: op by op, a cold command line spent 1.5 s on three logs' depths


def law_reach(fit: PressFit) -> np.ndarray:
    """(S,) the deepest depth each site's law was fitted to, m: the most that
    travel(t − lag) passed its press's onset in any press at the site (masked samples
    included: their input is in the model's memory)."""
    reach = np.zeros(len(fit.sites))
    for log, onsets, lag in zip(fit.logs, fit.onsets, fit.lags):
        inside = log.press >= 0
        depths = np.asarray(_depths(log.to_data(len(fit.sites)), jnp.asarray(onsets), jnp.asarray(lag.value)))  # the model's own
        np.maximum.at(reach, log.press_site[log.press[inside]], depths[inside])
    return reach


def channel_law(fit: PressFit) -> dict:
    """The channel law of a fit, as material.json's `channel_law`."""
    sites = []
    reach = law_reach(fit)
    for s, position in enumerate(fit.sites):
        sites.append({
            "position_m": [float(v) for v in position] if np.all(np.isfinite(position)) else [],
            "onset_m": float(fit.site_onsets[s]),
            "reach_m": float(reach[s]),
            "amplitudes_Pa": {name: [float(v) for v in fit.amplitudes[c, s]] for c, name in enumerate(fit.channels)},
        })
    return {
        "indentation": fit.indentation,
        "position_columns": list(fit.position_columns),
        "depth_scale_m": DEPTH_SCALE,
        "lag_s": float(np.mean([lag.value for lag in fit.lags])),
        "powers": list(POWERS),
        "channels": list(fit.channels),
        "sites": sites,
        **({"covariance_file": COVARIANCE_FILE} if fit.law_covariance is not None else {}),
    }


def residual_summary(fit: PressFit) -> list:
    """Per log and channel: RMS residual (Pa), R², masked samples."""
    out = []
    for log, residual in zip(fit.logs, fit.residuals):
        channels = {}
        for c, name in enumerate(fit.channels):
            used = log.mask[:, c]
            error = (residual[:, c] * log.noise[c])[used]
            observed = log.observed[used, c]
            variation = float(np.sum((observed - observed.mean()) ** 2))
            channels[name] = {
                "rms_Pa": float(np.sqrt(np.mean(error**2))) if used.any() else None,
                "r2": 1.0 - float(np.sum(error**2)) / variation if variation > 0 else None,
                "noise_Pa": float(log.noise[c]),
                "masked": int((~used).sum()),
            }
        out.append({"source": log.source, "channels": channels})
    return out


def make_press_report(fit: PressFit) -> dict:
    """The press fit's numbers as a JSON-ready dict."""
    return {
        "generator": f"hydrotact {__version__}",
        "mode": "lumped",
        "model": "press",
        "solver": fit.solver,
        "num_terms": fit.num_terms,
        "converged": fit.converged,
        "num_steps": fit.num_steps,
        "num_starts": fit.num_starts,
        "start_chi_squares": [float(c) for c in fit.start_chi_squares],
        "chi_square": fit.chi_square,
        "solver_chi_square": fit.solver_chi_square,
        "dof": fit.dof,
        "reduced_chi_square": fit.reduced_chi_square,
        "modulus_scale": "relative",
        "drift": fit.drift,
        "drift_from": fit.drift_from,
        "prony_terms": [{"ratio": r.to_json(), "tau_s": t.to_json()} for r, t in zip(fit.ratios, fit.taus)],
        "logs": [
            {
                "source": log.source,
                **({"sha256": file_digest(log.source)} if file_digest(log.source) else {}),
                "lag_s": lag.to_json(),
                "presses": [
                    {"site": int(site), "onset_m": float(onset), "onset_std_m": float(std)}
                    for site, onset, std in zip(log.press_site, onsets, stds)
                ],
            }
            for log, lag, onsets, stds in zip(fit.logs, fit.lags, fit.onsets, fit.onset_stds)
        ],
        "channel_law": channel_law(fit),
        "residuals": residual_summary(fit),
        "skipped": fit.skipped,
        "warnings": fit.warnings,
    }


def write_press_fit_outputs(fit: PressFit, out_dir, paths=(), plot=None) -> dict:
    """material.json, report.json, the channel law's covariance (COVARIANCE_FILE,
    numpy's npz: `qq`, `qa`, `aa` of :func:`hydrotact.sysid.lumped._press_fit._law_covariance`,
    which `compare` turns into a prediction band) and, with `plot(fit, out_dir) ->
    {name: path}`, the plots in out_dir (each written atomically). Returns the
    report, with `files`."""
    out_dir = Path(out_dir)
    files = {}
    if fit.law_covariance is not None:
        files["law_covariance"] = str(out_dir / COVARIANCE_FILE)
        with atomic_path(files["law_covariance"]) as tmp:
            np.savez(tmp, **fit.law_covariance)
    return write_outputs(fit, out_dir, make_press_material(fit, paths), make_press_report(fit), plot, files=files)
