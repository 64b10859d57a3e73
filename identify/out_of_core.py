"""Identification of a recording larger than memory: SparseIdentifier's method on per-chunk normal equations.

    src = H5ChunkSource("long.h5")                 # daq.h5source, or a Recording in memory
    ident = ChunkedIdentifier(chunk_samples=2**20).fit_source(src)
    ident.result()                                  # the document SparseIdentifier.result() gives

Steps, each with memory bounded by the chunk (identify.chunked):
1. one scan of the record: the band, the detrending, the valid rows (ChunkedChain.scan);
2. the held-out blocks of the in-core identifier (identifier.holdout_blocks: 50 blocks over the valid
   rows, 20 % held out, interleaved); each chunk's states from the chunked chain, its library Grams
   added into the blocks it overlaps (a block spans chunks, a chunk spans blocks: the sums are the
   same either way). Chunks are independent given the scan, so `map_chunks` may spread them over
   Dask workers (shakeid.cli passes a client's map);
3. from the summed BlockGram on: SparseIdentifier's own path, selection, all-rows refit, block-robust
   standard errors and inclusion probabilities (inherited, not copied: identical decisions on identical
   normal equations);
4. validation: free run on held-out windows (below), each started from the measured state.

What is not done out of core, and why (also in result()["out_of_core"]):
- SIMEX chain bias (identify.uncertainty.chain_bias): 16 replicates of the chain on fresh noise would
  read and transform the whole record 16 more times; the coefficients are reported without the bias
  correction and the standard errors are the block-robust ones (on long records the bias, a multiple
  of the noise variance, stays while the standard errors shrink: a known limitation).
- the displacement below the band for even forces (identify.inband.carry_offset): it solves for a slow
  displacement over the whole record. When the selected force has an even part the result says so.
- budget="free-run" and refine="free-run": both simulate the whole fit rows repeatedly; refused.

Validation by free run on windows: a free run over 1e8 samples costs as much as the rest together
and, started once, scores mostly how a phase error accumulates over hours. Instead, from each held-out
block a window of up to VALIDATION_WINDOW_S seconds (plus a guard at each end) is simulated from the
measured state at its start; the simulated states pass through the band on the window (as in
identify.validation.free_run), the guard (taper + LIVE_EDGE_PERIODS periods of f_lo, the chain's own
guard for a live edge) is dropped, and the fit metrics are those of identify.validation over all
windows' scored rows together; the verdict is identify.validation.fit_verdict's.
"""
from __future__ import annotations

import os
import socket
import time
from collections import Counter

import numpy as np

from .chunked import CHUNK_SAMPLES, ChunkedChain, chunk_ranges
from .errors import IdentificationError
from .gram import BlockGram
from .identifier import SparseIdentifier, effective_samples, holdout_blocks
from .inband import has_even_force
from .library import Library
from .model import SparseModel
from .validation import first_equation, fit_metrics, fit_verdict, free_run

#: Scored length of each held-out validation window (s); the 10 held-out blocks of a 13-hour record
#: give 10 minutes of free run in all.
VALIDATION_WINDOW_S = 60.0
SIMEX_SKIPPED = ("not done out of core: its replicates would read and transform the whole record once "
                 "each; coefficients are not corrected for the chain's bias and standard errors are block-robust only")


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

    def fit_source(self, source, progress=None, map_chunks=None) -> "ChunkedIdentifier":
        """Identify the record of a chunk source (identify.chunked). progress(stage, done, total) after
        each chunk; map_chunks(fn, jobs) -> iterable of fn(*job) results, any order (default: in turn)."""
        if self.refine is not None or (self.budget == "free-run" and self.max_terms is not None):
            raise IdentificationError("free-run budgets and refinement simulate the whole record repeatedly: "
                                      "not available out of core")
        self._optimizer()
        timings = {}
        t0 = time.perf_counter()
        chain = ChunkedChain.scan(source, self.band_hz, self.harmonics, self.taper_s, self.chunk_samples, progress)
        timings["scan"] = time.perf_counter() - t0
        sig = chain.summary()
        self.recording_ = None  # no SIMEX (see module doc)
        self.source_, self.chain_, self.states_ = source, chain, sig
        self.library_ = lib = Library(("q1", "q2"), (sig.input_name,), self.degree, self.extra_terms)
        edges, held = holdout_blocks(sig, self.holdout_fraction, self.holdout_samples)
        self.edges_, self.held_ = edges, held
        t0 = time.perf_counter()
        gram = self._chunked_gram(source, chain, edges, progress, map_chunks)
        timings["chain_library_gram"] = time.perf_counter() - t0
        train, heldout, coefs = self._fit_pass(effective_samples(sig), gram, held, timings)
        self.training_model_ = SparseModel(coefs, ("q1", "q2"), (sig.input_name,))
        self.budget_, self.refinement_ = None, None
        self.offset_ = {"carried": False, "passes": 0}
        t0 = time.perf_counter()
        reported, self.standard_errors_, self.uncertainty_ = self._trust(gram, held, effective_samples(sig), None)
        self.uncertainty_["chain_bias_skipped"] = SIMEX_SKIPPED
        timings["refit_uncertainty"] = time.perf_counter() - t0
        self.model_ = SparseModel(reported, ("q1", "q2"), (sig.input_name,), self.standard_errors_)
        self.validation_ = None
        if self.validate:
            t0 = time.perf_counter()
            self.validation_ = self._validate_windows(self.training_model_, progress)
            timings["validation"] = time.perf_counter() - t0
        if self.validation_ is not None and self.validation_.pop("even_force"):
            self.offset_["note"] = ("the selected force has an even part; its displacement below the band is "
                                    "not carried out of core (identify.out_of_core)")
        self.verdict_ = fit_verdict(self.validation_, self.training_model_, self.model_, sig.input_name)
        self.timings_ = timings
        return self

    def _chunked_gram(self, source, chain, edges, progress, map_chunks) -> BlockGram:
        """BlockGram over `edges` summed from per-chunk Grams (chunk_gram)."""
        lib = self.library_
        gram = BlockGram.__new__(BlockGram)
        gram._setup(edges, len(lib) + 2, 2)
        jobs = [(source, chain, lib, edges, a, b) for a, b in chunk_ranges(0, int(edges[-1]), self.chunk_samples)]
        where = Counter()
        for done, (blocks, C, host) in enumerate((map_chunks or _serial_map)(chunk_gram, jobs), start=1):
            gram.C[blocks] += C
            where[host] += 1
            if progress:
                progress("gram", done, len(jobs))
        self.computed_on_ = dict(where)  # chunks per process ("host:pid")
        return gram

    def _windows(self) -> list[tuple[int, int, int, int]]:
        """(start, stop, scored start, scored stop) in record samples of each validation window: the
        middle of a held-out block, up to window_s long, scored; a guard on each side (into the
        neighbouring blocks, never scored) lets the start's transient and the band's edge effects decay."""
        chain, edges = self.chain_, self.edges_
        guard = chain.taper_n + chain.live_guard
        scored = int(round(self.window_s * chain.fs_hz))
        v0, nv = chain.valid.start, int(edges[-1])
        out = []
        for k in np.flatnonzero(self.held_) if self.held_.any() else range(len(edges) - 1):
            a, b = int(edges[k]), int(edges[k + 1])
            s = min(scored, b - a)
            sa = a + (b - a - s) // 2
            out.append((v0 + max(sa - guard, 0), v0 + min(sa + s + guard, nv), v0 + sa, v0 + sa + s))
        return out

    def _validate_windows(self, model: SparseModel, progress=None) -> dict:
        """identify.validation.validate's document, over the held-out windows (module doc)."""
        names = ("q1_dot", "q1", "q2")
        measured, simulated = {k: [] for k in names}, {k: [] for k in names}
        one_step = []
        diverged, substeps, samples_per_step, even = False, 0, None, False
        windows = self._windows()
        for i, (a, b, ka, kb) in enumerate(windows):
            sig = self.chain_.signals(self.source_, a, b)
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
            if progress:
                progress("validation windows", i + 1, len(windows))
        cat = {k: (np.concatenate(measured[k]), np.concatenate(simulated[k])) for k in names}
        metrics = {k: fit_metrics(*cat[k]) for k in names}
        return {"diverged": diverged, "substeps": substeps, "samples_per_step": samples_per_step, "heldout": metrics,
                "all": {k: None for k in names},  # not simulated: the whole record is never free-run
                "heldout_samples": int(cat["q1"][0].size),
                "equation_error": {"q1_dot": fit_metrics(cat["q1_dot"][0], np.concatenate(one_step))},
                "windows": {"count": len(windows), "scored_s": float(self.window_s),
                            "scored_starts": [int(w[2]) for w in windows],
                            "method": "free run from the measured state on each held-out window"},
                "even_force": even}

    def result(self) -> dict:
        """SparseIdentifier.result(), its row counts from the blocks, plus an "out_of_core" section."""
        self.heldout_rows_ = np.zeros(0, dtype=bool)  # never materialised: counted from the blocks below
        out = super().result()
        counts = np.diff(self.edges_)
        out["chain"]["fit_samples"] = int(counts[~self.held_].sum())
        out["chain"]["heldout_samples"] = int(counts[self.held_].sum())
        out["out_of_core"] = {
            "samples": int(self.chain_.n), "chunk_samples": int(self.chunk_samples),
            "overlap_samples": int(self.chain_.overlap),
            "chunks": len(chunk_ranges(0, int(self.edges_[-1]), self.chunk_samples)),
            "chain_bias": SIMEX_SKIPPED, "computed_on": self.computed_on_,
            "validation": f"free run on {self.validation_['windows']['count'] if self.validation_ else 0} "
                          f"held-out windows of {self.window_s:g} s, each from its measured state",
        }
        return out
