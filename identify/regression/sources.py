"""Normal-equations sources: what the one fit sequence (identify.fitting) needs of each recording.

A source gives its chain's states (`sig`: in core the states themselves, out of core their summary:
band, valid rows, sample rate, input name), its per-block normal equations on given block edges (a
BlockGram), what the chain bias and the noise's share of the variance read of it (uncertainty.RecordNoise's
methods), and its free-run validation document. In core: RecordingEquations here; out of core:
identify.out_of_core.ChunkedEquations. Everything decided from these is the same code.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from ..chain.states import StateSignals, reconstruct_states
from .gram import BlockGram
from ..chain.inband import band_limited_gram, carry_offset, has_even_force
from ..model import SparseModel
from ..trust.uncertainty import RecordNoise
from ..simulation.validation import validate


def state_gram(library, sig: StateSignals, edges, columns=None) -> BlockGram:
    """Per-block normal equations of the library on in-core states. With an offset carried (an even
    force) every column goes through the chain's band (identify.chain.inband, as explain's screen does): an
    even term's DC and slow part are not in the measured acceleration, and on raw columns an offset a
    few % off shows as a spurious constant, q1^4, q2^4 (3e4 N/m^2 rig). Without one (odd forces) the
    columns stay as they are and are streamed in chunks: through the band, the degree-4 even terms fit
    the chain's low-frequency error on short sweeps (exact supports 9 of 24 instead of 21 of 24,
    docs/identification.md), while raw, their DC costs. `columns`: those library columns only."""
    lib = library if columns is None else library.subset(columns)
    v = sig.valid
    # q2_dot = q1 by construction of the chain, so the second target is q1 itself
    targets = (sig.q1_dot[v], sig.q1[v])
    if sig.q2_offset is not None:
        return band_limited_gram(lib, sig, targets, edges)
    return BlockGram.from_library(lib, (sig.q1[v], sig.q2[v]), sig.input[v][:, None], targets, edges)


class NormalEquationsSource(Protocol):
    """One recording as the fit sequence reads it (module doc)."""

    name: str
    sig: StateSignals
    in_core: bool  # its states are held in memory (free-run budget and refinement need them)

    def gram(self, library, edges, columns=None) -> BlockGram:
        """Per-block normal equations of the library (or its `columns`) and targets (q1_dot, q1)."""

    def even_force(self, model: SparseModel) -> bool:
        """Whether the model's force has an even part the source can carry a displacement below the band for."""

    def carry_offset(self, library, edges, fit_blocks):
        """(source with the displacement below the band carried, its BlockGram, the offset's summary)."""

    def noise_floors(self):
        """White-noise std of (input, output), None where it cannot be read (uncertainty.noise_floors)."""

    def noise_model(self):
        """The chain's image of white noise on the record (chain_noise.BandLimitedNoise)."""

    def moment_sum(self, k: tuple) -> float:
        """Sum over the valid rows of the monomial of (q1, q2, q1_dot, input) with exponents k."""

    def score_pieces(self, noise, floor) -> list:
        """noise_spread.noise_variance's parts for this recording."""

    def simex_inputs(self):
        """(recording, states) for SIMEX's replicates, or None where the record is not in memory."""

    def bias_unavailable(self, method: str) -> str:
        """Why the chain bias could not be estimated here when it was not ("" when nothing stands in the way)."""

    def validate(self, model: SparseModel, edges, held) -> tuple[dict, object]:
        """(validation document, run for pooling across recordings or None) of the model's free run."""


class RecordingEquations(RecordNoise):
    """A recording in memory: the whole-record chain (identify.chain.states), its states' Grams streamed
    (fitting.state_gram), the displacement below the band for even forces (identify.chain.inband) and the
    free run over the whole valid span (validation.validate)."""

    in_core = True

    def __init__(self, recording, sig: StateSignals):
        super().__init__(recording, sig)
        self.name = recording.source

    @classmethod
    def read(cls, recording, params) -> "RecordingEquations":
        """The chain on `recording` with the identifier's band_hz, harmonics and taper_s."""
        return cls(recording, reconstruct_states(recording, params.band_hz, params.harmonics, params.taper_s))

    def gram(self, library, edges, columns=None) -> BlockGram:
        return state_gram(library, self.sig, edges, columns)

    def even_force(self, model: SparseModel) -> bool:
        return has_even_force(model, self.sig)

    def carry_offset(self, library, edges, fit_blocks):
        sig, gram, offset = carry_offset(library, self.sig, edges, fit_blocks)
        return RecordingEquations(self.recording, sig), gram, offset

    def simex_inputs(self):
        return self.recording, self.sig

    def bias_unavailable(self, method: str) -> str:
        return ""

    def validate(self, model: SparseModel, edges, held):
        rows = np.repeat(held, np.diff(edges))
        mask = rows if held.any() else np.ones_like(rows)
        doc, sim_states, sim_qdot = validate(model, self.sig, mask)
        return doc, (self.sig, mask, sim_states, sim_qdot, doc)
