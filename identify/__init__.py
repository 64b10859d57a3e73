"""shakeid's identification engine: recordings in, a validated sparse nonlinear ODE model with its trust out,
and the explanation of a model's misfit. The names below are the public API (README, docs, benchmarks use
them); the folders are the pipeline's stages, each a hop from here:

    data/        recordings, channels, file readers, data quality
    chain/       measurement chain: channels -> states (q1, q2, q1_dot), band, spectra, bias correction, chunks
    noise/       sensor-noise floor, the chain's image of white noise
    regression/  terms, the library, normal equations (BlockGram) and their sources, optimizers/
    selection/   the Pareto choice and refit, the free-run term budget
    trust/       standard errors, inclusion probabilities, the noise's share of the variance
    simulation/  free run, validation, output-error refine, multiple shooting
    explain/     the discrepancy workflow and its catalog of effects (explain/effects/)
    frf/         nonlinear frequency response (harmonic balance, folds, backbone, measured envelopes)
    export/      model export (Python, C, LaTeX, FMU)

The estimator and its one fit sequence sit at the top: identifier.py (SparseIdentifier), params.py (its
parameters, declared once), fitting.py (the sequence), joint.py (several recordings), out_of_core.py
(records larger than memory), model.py (SparseModel).

Names load on first use (PEP 562), so `import identify.errors` does not load the whole engine."""
from __future__ import annotations

from importlib import import_module

_PUBLIC = {
    "SparseIdentifier": "identify.identifier",
    "ChunkedIdentifier": "identify.out_of_core",
    "SparseModel": "identify.model",
    "Recording": "identify.data.recording",
    "read_recording": "identify.data.recording",
    "simulate": "identify.simulation.simulate",
    "DiscrepancyAnalysis": "identify.explain.workflow",
    "frequency_response": "identify.frf",
    "backbone": "identify.frf",
    "export_model": "identify.export",
    "ShakeidError": "identify.errors",
    "RecordingError": "identify.errors",
    "ModelError": "identify.errors",
    "IdentificationError": "identify.errors",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        return getattr(import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'identify' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC))
