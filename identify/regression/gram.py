"""Normal equations per block of samples.

The library matrix A (n x m) and targets Y (n x p) are reduced once to per-block cross-products
[A Y]^T [A Y] over contiguous sample blocks. `BlockGram.from_library` never materialises A: it
evaluates the library in cache-sized row chunks into one reused buffer and accumulates, so memory is
O(chunk) and no time goes to page-faulting an n x m matrix (benchmarks/identify_speed.py). Everything downstream (LASSO path, MSE along it, held-out
error, least-squares refit, block-robust standard errors) works on these (m+p)^2 numbers per block, so
its cost does not grow with the record length.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..threads import one_blas_thread

#: Rows per chunk when streaming the library: 8192 x 18 doubles = 1.2 MB, resident in L2/L3 cache.
CHUNK_ROWS = 8192


@dataclass
class NormalEquations:
    """Sums over a set of samples: G = A^T A, B = A^T Y, yy = diag(Y^T Y), n samples."""

    G: np.ndarray
    B: np.ndarray
    yy: np.ndarray
    n: int

    def mse(self, X: np.ndarray, eq: int | None = None) -> np.ndarray:
        """Mean squared residual of coefficient columns X (m, k) for target `eq` (or X (m, p) all)."""
        if eq is None:
            return (self.yy - 2 * np.einsum("ij,ij->j", self.B, X) + np.einsum("ij,ij->j", X, self.G @ X)) / self.n
        b = self.B[:, eq][:, None]
        return (self.yy[eq] - 2 * (b * X).sum(0) + np.einsum("ij,ij->j", X, self.G @ X)) / self.n


class BlockGram:
    """Per-block cross-products of [A | Y] over contiguous blocks of rows; `edges` are the block
    boundaries (row indices, first 0, last n). `segment` (n_blocks,) numbers the recording each block
    comes from (all 0 for one record; BlockGram.concatenate): neighbouring blocks of different
    segments are not contiguous in time."""

    def __init__(self, AY: np.ndarray, n_targets: int, edges: np.ndarray):
        n, w = AY.shape
        self._setup(edges, w, n_targets)
        for b in range(self.n_blocks):
            blk = AY[self.edges[b]:self.edges[b + 1]]
            self.C[b] = blk.T @ blk

    def _setup(self, edges, width: int, n_targets: int):
        self.edges = np.asarray(edges, dtype=int)
        self.m = width - n_targets
        self.p = n_targets
        self.C = np.zeros((self.edges.size - 1, width, width))
        self.counts = np.diff(self.edges)
        self.segment = np.zeros(self.edges.size - 1, dtype=int)

    @classmethod
    def zeros(cls, edges, width: int, n_targets: int) -> "BlockGram":
        """Empty per-block sums over `edges` of `width` columns (the last n_targets the targets), to be
        added into block by block (a record read in chunks: identify.out_of_core)."""
        self = cls.__new__(cls)
        self._setup(edges, width, n_targets)
        return self

    def add(self, blocks, C: np.ndarray) -> None:
        """Add cross-products C (len(blocks), width, width) into the given blocks."""
        self.C[blocks] += C

    @classmethod
    def concatenate(cls, grams) -> "BlockGram":
        """One BlockGram of several recordings' (same library and targets): blocks stacked in order,
        edges continued across recordings (rows of the concatenated records), segment = the recording's
        index. Sums over its blocks are the summed normal equations of all recordings."""
        grams = list(grams)
        self = cls.__new__(cls)
        starts = np.cumsum([0] + [int(g.edges[-1]) for g in grams[:-1]])
        edges = np.concatenate([[0]] + [g.edges[1:] + s for g, s in zip(grams, starts)])
        self._setup(edges, grams[0].m + grams[0].p, grams[0].p)
        self.C = np.concatenate([g.C for g in grams])
        self.segment = np.concatenate([np.full(g.n_blocks, i) for i, g in enumerate(grams)])
        return self

    def part(self, segment: int) -> "BlockGram":
        """The blocks of one segment (recording) as a BlockGram of its own (edges from 0)."""
        idx = np.flatnonzero(self.segment == segment)
        out = BlockGram.__new__(BlockGram)
        edges = self.edges[idx[0]: idx[-1] + 2]
        out._setup(edges - edges[0], self.m + self.p, self.p)
        out.C = self.C[idx]
        return out

    @classmethod
    @one_blas_thread  # ~120 small GEMMs per 1e6 samples: slower with 2 threads, oversubscribed under load
    def from_library(cls, library, states, inputs, targets, edges, chunk: int | None = None) -> "BlockGram":
        """Per-block Grams of [library(states, inputs) | targets] without building the whole matrix.

        states, targets : sequences of 1-D arrays (columns); inputs : (n, n_inputs) array; chunk : rows
        per chunk (default: CHUNK_ROWS x 18 columns' worth, so a narrow library takes longer chunks and
        pays the per-chunk overhead less often)."""
        self = cls.__new__(cls)
        m, p = len(library), len(targets)
        if chunk is None:
            chunk = CHUNK_ROWS * 18 // max(m + p, 18) if m + p >= 18 else CHUNK_ROWS * 18 // (m + p)
        self._setup(edges, m + p, p)
        buf = np.empty((chunk, m + p), order="F")
        for b in range(self.n_blocks):
            for r0 in range(self.edges[b], self.edges[b + 1], chunk):
                r1 = min(r0 + chunk, self.edges[b + 1])
                view = buf[: r1 - r0]
                library.evaluate([s[r0:r1] for s in states], inputs[r0:r1], out=view[:, :m])
                for j, y in enumerate(targets):
                    view[:, m + j] = y[r0:r1]
                self.C[b] += view.T @ view
        return self

    @property
    def n_blocks(self) -> int:
        return self.C.shape[0]

    def equations(self, blocks) -> NormalEquations:
        """Normal equations summed over the given block indices (or a boolean mask)."""
        idx = np.flatnonzero(blocks) if np.asarray(blocks).dtype == bool else np.asarray(blocks, dtype=int)
        C = self.C[idx].sum(0)
        m = self.m
        return NormalEquations(C[:m, :m], C[:m, m:], np.diag(C[m:, m:]).copy(), int(self.counts[idx].sum()))

    def block_scores(self, blocks, support: np.ndarray, x: np.ndarray, eq: int) -> np.ndarray:
        """Per-block sums of a_t * r_t on `support` (for sandwich standard errors), shape (k, |S|)."""
        idx = np.flatnonzero(blocks) if np.asarray(blocks).dtype == bool else np.asarray(blocks, dtype=int)
        C = self.C[idx]
        G = C[:, support][:, :, support]
        b = C[:, support, self.m + eq]
        return b - G @ x


def scaled_pinv(M: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """Pseudo-inverse of a symmetric positive semi-definite matrix, taken on its unit-diagonal scaling.

    Library columns differ in magnitude by many orders (the normal matrix's condition number reaches
    ~1e20 in raw units, ~10 after scaling columns to unit RMS). `pinv` of the raw matrix cuts singular
    values relative to the largest, which silently drops the directions of small-valued columns and
    makes their variances wrong by orders of magnitude; on the scaled matrix only true collinearity is
    cut. M^+ = D^-1 (D^-1 M D^-1)^+ D^-1 with D = sqrt(diag M)."""
    d = np.sqrt(np.maximum(np.diag(M), 0.0))
    d = np.where(d > 0, d, 1.0)
    return np.linalg.pinv(M / np.outer(d, d), rcond=rcond, hermitian=True) / np.outer(d, d)


def sandwich_covariance(gram: BlockGram, blocks, G: np.ndarray, support: np.ndarray, x: np.ndarray,
                        eq: int) -> np.ndarray:
    """Block-robust (cluster sandwich) covariance of least-squares coefficients x on `support`.

    Residuals of a band-limited record are correlated over many samples, so the i.i.d. formula
    understates the uncertainty; block scores (sums of a_t r_t over each block) are nearly independent.
    G is the normal matrix of the fit (sum over the same blocks)."""
    scores = gram.block_scores(blocks, support, x, eq)
    k = scores.shape[0]
    bread = scaled_pinv(G[np.ix_(support, support)])
    return bread @ (scores.T @ scores * k / max(k - 1, 1)) @ bread
