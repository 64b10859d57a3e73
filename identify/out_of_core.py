"""Identification of a recording larger than memory: SparseIdentifier's method on per-chunk normal equations.

    src = H5ChunkSource("long.h5")                 # daq.h5source, or a Recording in memory
    ident = ChunkedIdentifier(chunk_samples=2**20).fit_source(src)
    ident.result()                                  # the document SparseIdentifier.result() gives

Steps, each with memory bounded by the chunk (identify.chain.chunked):
1. one scan of the record: the band, the detrending, the valid rows (ChunkedChain.scan);
2. the held-out blocks of the in-core identifier (identifier.holdout_blocks: 50 blocks over the valid
   rows, 20 % held out, interleaved); each chunk's states from the chunked chain, its library Grams
   added into the blocks it overlaps (a block spans chunks, a chunk spans blocks: the sums are the
   same either way). Chunks are independent given the scan, so `map_chunks` may spread them over
   Dask workers (shakeid.cli passes a client's map);
3. from the summed BlockGram on: the one fit sequence (identify.fitting): path, selection, all-rows
   refit, the chain's bias in closed form, standard errors and inclusion probabilities, the same code
   as in core on the same normal equations. The closed-form bias (identify.chain.bias_correction) reads the noise
   floors from the scan's spectra and the noise covariance from the band, and its raw moments from the
   Gram: no pass over the record. The noise's share of the variance (identify.trust.noise_spread) needs the
   score's transforms: one more pass, chunk by chunk, each chunk's rows paired with an overlap of
   NOISE_OVERLAP (the chain's overlap) on each side (ChunkedEquations.score_pieces);
4. validation: free run on held-out windows (below), each started from the measured state.

What is not done out of core, and why (also in result()["out_of_core"]):
- SIMEX (bias_method="simex", or kept terms that are not monomials of the states and input, sign(q1),
  |q1|, ...): its replicates would read and transform the whole record once each; the coefficients of
  such a fit are reported without the chain-bias correction, and uncertainty.chain_bias_skipped says so.
- the displacement below the band for even forces (identify.chain.inband.carry_offset): it solves for a slow
  displacement over the whole record. When the selected force has an even part the result says so.
- budget="free-run" and refine="free-run": both simulate the whole fit rows repeatedly; refused.

Validation by free run on windows: a free run over 1e8 samples costs as much as the rest together
and, started once, scores mostly how a phase error accumulates over hours. Instead, from each held-out
block a window of up to VALIDATION_WINDOW_S seconds (plus a guard at each end) is simulated from the
measured state at its start; the simulated states pass through the band on the window (as in
identify.simulation.validation.free_run), the guard (taper + LIVE_EDGE_PERIODS periods of f_lo, the chain's own
guard for a live edge) is dropped, and the fit metrics are those of identify.simulation.validation over all
windows' scored rows together; the verdict is identify.simulation.validation.fit_verdict's.
"""
from __future__ import annotations

import os
import socket
import time
from collections import Counter

import numpy as np

from .noise.chain_noise import BandLimitedNoise
from .chain.chunked import CHUNK_SAMPLES, ChunkedChain, chunk_ranges
from .errors import IdentificationError
from .fitting import fit_sources
from .regression.gram import BlockGram
from .identifier import SparseIdentifier
from .chain.inband import has_even_force
from .explain.effects import expand_terms
from .regression.library import Library
from .model import SparseModel
from .threads import one_blas_thread
from .trust.uncertainty import floors_read, noise_floors
from .simulation.validation import first_equation, fit_metrics, free_run

#: Scored length of each held-out validation window (s); the 10 held-out blocks of a 13-hour record
#: give 10 minutes of free run in all.
VALIDATION_WINDOW_S = 60.0
SIMEX_SKIPPED = ("SIMEX is not done out of core: its replicates would read and transform the whole record once "
                 "each; coefficients are not corrected for the chain's bias (the closed form needs every kept term "
                 "a monomial of the states and input)")
#: The noise covariance (a lag-0 sum over the band's bins, nearly independent of the length it is taken
#: on) from at most this many samples' bins: 1e8 samples' would hold ~400 MB of filter responses.
COVARIANCE_SAMPLES = 1 << 22


def chunk_gram(source, chain: ChunkedChain, library: Library, edges: np.ndarray, a: int, b: int):
    """Grams of the library and targets on valid rows [a, b) (valid-row coordinates), split by the blocks
    of `edges`: (block indices, (k, m + p, m + p) cross-products, "host:pid" that computed them). Runs
    anywhere the source can be read (a Dask worker: identify.out_of_core's map_chunks)."""
    v0 = chain.valid.start
    q1, q2, q1_dot, u = chain.states(source, v0 + a, v0 + b)
    first = int(np.searchsorted(edges, a, side="right")) - 1
    last = int(np.searchsorted(edges, b, side="left"))  # blocks first .. last - 1 overlap [a, b)
    local = np.clip(edges[first:last + 1], a, b) - a
    part = BlockGram.from_library(library, (q1, q2), u[:, None], (q1_dot, q1), local)
    return np.arange(first, last), part.C, f"{socket.gethostname()}:{os.getpid()}"


def _serial_map(fn, jobs):
    for job in jobs:
        yield fn(*job)


class ChunkedEquations:
    """A record read in chunks as the fit sequence's source (identify.regression.sources.NormalEquationsSource):
    the chunked chain's Grams (chunk_gram, over map_chunks), its noise read chunk by chunk, and the free
    run on held-out windows."""

    in_core = False

    def __init__(self, source, chain: ChunkedChain, chunk_samples: int, window_s: float, progress=None,
                 map_chunks=None):
        self.source, self.chain, self.chunk_samples, self.window_s = source, chain, int(chunk_samples), window_s
        self.progress, self.map_chunks, self.name = progress, map_chunks, source.source
        self.sig = chain.summary()
        self.computed_on: dict = {}

    def _ranges(self, stop: int) -> list:
        return chunk_ranges(0, stop, self.chunk_samples)

    def gram(self, library, edges, columns=None) -> BlockGram:
        """BlockGram over `edges` summed from per-chunk Grams (chunk_gram)."""
        if columns is not None:
            raise IdentificationError("Grams of library columns re-read the record: not done out of core")
        gram = BlockGram.zeros(edges, len(library) + 2, 2)
        jobs = [(self.source, self.chain, library, edges, a, b) for a, b in self._ranges(int(edges[-1]))]
        where = Counter()
        for done, (blocks, C, host) in enumerate((self.map_chunks or _serial_map)(chunk_gram, jobs), start=1):
            gram.add(blocks, C)
            where[host] += 1
            if self.progress:
                self.progress("gram", done, len(jobs))
        self.computed_on = dict(where)  # chunks per process ("host:pid")
        return gram

    def even_force(self, model: SparseModel) -> bool:
        return False  # not carried out of core: the validation windows say when it has one

    def carry_offset(self, library, edges, fit_blocks):
        raise IdentificationError("the displacement below the band is not carried out of core")

    def noise_floors(self):
        s = self.sig
        if s.spectra is not None:
            return noise_floors(self.source, s.band_hz, s.spectra)  # the scan's spectra: fs_hz is all it reads
        return floors_read(lambda a, b: self.source.read(a, b), int(self.chain.n), s.fs_hz, s.band_hz)

    def noise_model(self) -> BandLimitedNoise:
        c = self.chain
        return BandLimitedNoise(min(int(c.n), COVARIANCE_SAMPLES), c.fs_hz, c.band_hz, c.layout)

    def _valid_states(self, a: int, b: int):
        """(q1, q2, q1_dot, input) on valid rows [a, b) (valid-row coordinates)."""
        v0 = self.chain.valid.start
        return self.chain.states(self.source, v0 + a, v0 + b)

    def moment_sum(self, k: tuple) -> float:
        """A raw moment the Gram lacks: one pass over the valid rows."""
        total = 0.0
        for a, b in self._ranges(self.chain.valid.stop - self.chain.valid.start):
            y = self._valid_states(a, b)
            col = np.ones_like(y[0])
            for v, p in enumerate(k):
                if p:
                    col = col * y[v] ** p
            total += float(col.sum())
        return total

    def score_pieces(self, noise, floor):
        """Per chunk of valid rows, (its rows with NOISE_OVERLAP on each side, the noise on that stretch,
        floor, the chunk's slice in it): noise_spread.noise_variance pairs each chunk's rows with those
        within the overlap, which is the whole record's sum up to the noise's correlation beyond it."""
        c, nv = self.chain, self.chain.valid.stop - self.chain.valid.start
        reach = c.overlap
        ranges = self._ranges(nv)
        for i, (a, b) in enumerate(ranges):
            ea, eb = max(a - reach, 0), min(b + reach, nv)
            y = self._valid_states(ea, eb)
            yield y, BandLimitedNoise(eb - ea, c.fs_hz, c.band_hz, c.layout), floor, slice(a - ea, b - ea)
            if self.progress:
                self.progress("noise share", i + 1, len(ranges))

    def simex_inputs(self):
        return None

    def bias_unavailable(self, method: str) -> str:
        return SIMEX_SKIPPED

    def windows(self, edges, held) -> list[tuple[int, int, int, int]]:
        """(start, stop, scored start, scored stop) in record samples of each validation window: the
        middle of a held-out block, up to window_s long, scored; a guard on each side (into the
        neighbouring blocks, never scored) lets the start's transient and the band's edge effects decay."""
        chain = self.chain
        guard = chain.taper_n + chain.live_guard
        scored = int(round(self.window_s * chain.fs_hz))
        v0, nv = chain.valid.start, int(edges[-1])
        out = []
        for k in np.flatnonzero(held) if held.any() else range(len(edges) - 1):
            a, b = int(edges[k]), int(edges[k + 1])
            s = min(scored, b - a)
            sa = a + (b - a - s) // 2
            out.append((v0 + max(sa - guard, 0), v0 + min(sa + s + guard, nv), v0 + sa, v0 + sa + s))
        return out

    def validate(self, model: SparseModel, edges, held):
        """identify.simulation.validation.validate's document, over the held-out windows (module doc); no run to
        pool (one record out of core)."""
        names = ("q1_dot", "q1", "q2")
        measured, simulated = {k: [] for k in names}, {k: [] for k in names}
        one_step = []
        diverged, substeps, samples_per_step, even = False, 0, None, False
        windows = self.windows(edges, held)
        for i, (a, b, ka, kb) in enumerate(windows):
            sig = self.chain.signals(self.source, a, b)
            even = even or has_even_force(model, sig)
            sim, qdot, used, div, stride = free_run(model, sig)
            substeps = max(substeps, int(used))
            samples_per_step = int(stride) if samples_per_step is None else min(samples_per_step, int(stride))
            diverged = diverged or bool(div)
            keep = slice(ka - a, kb - a)
            for k, m, s in zip(names, (sig.q1_dot, sig.q1, sig.q2), (qdot, sim[:, 0], sim[:, 1])):
                measured[k].append(m[keep])
                simulated[k].append(s[keep])
            one_step.append(first_equation(model, sig.q1[keep], sig.q2[keep], sig.input[keep][:, None]))
            if self.progress:
                self.progress("validation windows", i + 1, len(windows))
        cat = {k: (np.concatenate(measured[k]), np.concatenate(simulated[k])) for k in names}
        metrics = {k: fit_metrics(*cat[k]) for k in names}
        self.even_force_seen = even
        return {"diverged": diverged, "substeps": substeps, "samples_per_step": samples_per_step, "heldout": metrics,
                "all": {k: None for k in names},  # not simulated: the whole record is never free-run
                "heldout_samples": int(cat["q1"][0].size),
                "equation_error": {"q1_dot": fit_metrics(cat["q1_dot"][0], np.concatenate(one_step))},
                "windows": {"count": len(windows), "scored_s": float(self.window_s),
                            "scored_starts": [int(w[2]) for w in windows],
                            "method": "free run from the measured state on each held-out window"}}, None


class ChunkedIdentifier(SparseIdentifier):
    """SparseIdentifier's parameters, plus chunk_samples (samples per chunk, the memory bound) and
    window_s (scored seconds per held-out validation window). Fit with fit_source(source)."""

    def __init__(self, *args, chunk_samples: int = CHUNK_SAMPLES, window_s: float = VALIDATION_WINDOW_S, **kw):
        super().__init__(*args, **kw)
        self.chunk_samples = chunk_samples
        self.window_s = window_s

    def fit(self, recording):
        """A Recording in memory, identified chunk by chunk (tests compare it with the in-core path)."""
        return self.fit_source(recording)

    @one_blas_thread  # as SparseIdentifier.fit (identify.threads)
    def fit_source(self, source, progress=None, map_chunks=None) -> "ChunkedIdentifier":
        """Identify the record of a chunk source (identify.chain.chunked). progress(stage, done, total) after
        each chunk; map_chunks(fn, jobs) -> iterable of fn(*job) results, any order (default: in turn)."""
        if self.refine is not None or (self.budget == "free-run" and self.max_terms is not None):
            raise IdentificationError("free-run budgets and refinement simulate the whole record repeatedly: "
                                      "not available out of core")
        self._check_options()
        timings = {}
        t0 = time.perf_counter()
        chain = ChunkedChain.scan(source, self.band_hz, self.harmonics, self.taper_s, self.chunk_samples, progress)
        timings["scan"] = time.perf_counter() - t0
        eqs = ChunkedEquations(source, chain, self.chunk_samples, self.window_s, progress, map_chunks)
        self.recording_, self.joint_, self.source_, self.chain_ = None, None, source, chain
        self.states_ = eqs.sig
        self.library_ = Library(("q1", "q2"), (eqs.sig.input_name,), self.degree, expand_terms(self.extra_terms))
        fit_sources(self, [eqs], timings)
        timings["chain_library_gram"] = timings.pop("library_gram")
        self.computed_on_ = eqs.computed_on
        if getattr(eqs, "even_force_seen", False):
            self.offset_["note"] = ("the selected force has an even part; its displacement below the band is "
                                    "not carried out of core (identify.out_of_core)")
        self.timings_ = timings
        return self

    def result(self) -> dict:
        """SparseIdentifier.result() plus an "out_of_core" section."""
        out = super().result()
        edges = self.blocks_[0][0]
        bias = self.uncertainty_.get("chain_bias")
        out["out_of_core"] = {
            "samples": int(self.chain_.n), "chunk_samples": int(self.chunk_samples),
            "overlap_samples": int(self.chain_.overlap),
            "chunks": len(chunk_ranges(0, int(edges[-1]), self.chunk_samples)),
            "chain_bias": bias["method"] if bias else self.uncertainty_.get("chain_bias_skipped"),
            "computed_on": self.computed_on_,
            "validation": f"free run on {self.validation_['windows']['count'] if self.validation_ else 0} "
                          f"held-out windows of {self.window_s:g} s, each from its measured state",
        }
        return out
