"""Silverbox, 7 terms: which estimation-only criterion could choose the terms that extrapolate best?

    python benchmarks/silverbox_criteria.py --part criteria   # ranking criteria of the two rival sets
    python benchmarks/silverbox_criteria.py --part refits     # other refit rows, 6 and 8 terms
    python benchmarks/silverbox_criteria.py --part wide       # the free-run budget over the whole library
    python benchmarks/silverbox_criteria.py --part output-error  # the budget on the output's error alone
    python benchmarks/silverbox_criteria.py --part second-record  # the distribution's second record

The free-run budget (identify.selection.budget) keeps {1, q1, q2, q2^2, q2^3, u} + q1^3; + q1*q2^2 instead scores
better on the arrowhead test set, which extrapolates beyond the estimation amplitudes. Here each rival is
refit on its free-run error (identify.simulation.refine) over estimation rows only and scored by several
estimation-only criteria (free-run error = sum over q2, q1 of MSE / variance, FreeRunError) and, for
the record only, on the test sets (benchmarks/silverbox.py's score, mV). Nothing from the test ranges
enters any fit or criterion. One JSON line per result. Figures: docs/identification.md (issue 11).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import silverbox as bench  # noqa: E402
from identify.selection.budget import choose_budget  # noqa: E402
from identify.regression.gram import BlockGram  # noqa: E402
from identify.identifier import SparseIdentifier, holdout_blocks  # noqa: E402
from identify.model import SparseModel  # noqa: E402
from identify.regression.optimizers.base import least_squares  # noqa: E402
from identify.data.recording import read_recording  # noqa: E402
from identify.simulation.refine import FreeRunError, refine_free_run  # noqa: E402
from identify.simulation.simulate import simulate  # noqa: E402

CORE = ["1", "q1", "q2", "q2^3", "u"]
SETS = {"chosen": CORE + ["q2^2", "q1^3"], "hand-picked": CORE + ["q2^2", "q1*q2^2"],
        "q1^3,q1^2*q2": CORE + ["q1^3", "q1^2*q2"], "equation-error": CORE + ["q1^2*q2", "q1*q2^2"],
        "6 Duffing prior": CORE + ["q2^2"], "8 both dampings": CORE + ["q2^2", "q1^3", "q1*q2^2"]}
N_AMPLITUDE_HELD = 10  # of the 50 blocks: the highest-peak ones, held out by the amplitude split


class Setup:
    """The default identification of the estimation range and the masks the criteria use."""

    def __init__(self, path: str):
        rec = read_recording(path, "force", "V1", "V2", fs_hz=bench.FS_HZ)
        self.u, self.y = rec.input, rec.output
        ident = SparseIdentifier(validate=False).fit(rec.slice(*bench.ESTIMATION))
        self.ident, self.sig, self.names = ident, ident.states_, ident.library_.names
        sig, v = self.sig, self.sig.valid
        self.edges, self.held = holdout_blocks(sig)
        self.gram = BlockGram.from_library(ident.library_, (sig.q1[v], sig.q2[v]), sig.input[v][:, None],
                                           (sig.q1_dot[v], sig.q1[v]), self.edges)
        q2 = np.abs(sig.q2[v])
        peak = np.maximum.reduceat(q2, self.edges[:-1])
        self.amp_held = np.zeros(peak.size, dtype=bool)
        self.amp_held[np.argsort(peak)[-N_AMPLITUDE_HELD:]] = True
        self.peaks = {"fit_blocks_max": float(peak[~self.amp_held].max()),
                      "held_blocks": [float(peak[self.amp_held].min()), float(peak[self.amp_held].max())]}
        self.top10_rows = q2 >= np.quantile(q2, 0.9)
        self.upper_half_rows = q2 >= np.median(q2)
        self.everything = np.ones_like(self.held)

    def rows(self, blocks: np.ndarray) -> np.ndarray:
        return np.repeat(blocks, np.diff(self.edges))

    def refit(self, terms, ls_blocks: np.ndarray, rows: np.ndarray | None, ftol: float = 1e-8) -> SparseModel:
        """Least squares on `ls_blocks`, then the free-run refit on `rows` (None: all interior rows)."""
        eqs_ls = self.gram.equations(ls_blocks)
        s = np.array([n in terms for n in self.names])
        x = least_squares(eqs_ls.G, eqs_ls.B[:, 0], s)
        eqs = {eq: dict(c) for eq, c in self.ident.model_.equations.items()}
        eqs["q1_dot"] = {self.names[j]: float(x[j]) for j in np.flatnonzero(s)}
        start = SparseModel(eqs, self.ident.model_.states, self.ident.model_.inputs)
        return refine_free_run(start, self.sig, rows, ftol=ftol)[0]

    def test(self, model: SparseModel) -> dict:
        substeps = FreeRunError(self.sig, None, model=model).substeps
        return {k: round(v, 4) for k, v in bench.score(model, self.u, self.y, substeps).items()}

    def multiple_shooting(self, model: SparseModel, rows: np.ndarray, length: int) -> float:
        """q2 error (MSE / variance on `rows`) of free runs over consecutive `length`-sample segments of
        `rows`, each started from the measured state (no band-limiting: segments are short)."""
        err = FreeRunError(self.sig, None, model=model)
        x, q2 = self.sig.states[self.sig.valid], self.sig.q2[self.sig.valid]
        s, out = err.substeps, []
        for a in range(self.sig.taper_n, x.shape[0] - length - self.sig.taper_n, length):
            if rows[a:a + length].all():
                sim = simulate(model, err.dt, x[a], inputs_fine=err.u_fine[a * 2 * s:(a + length - 1) * 2 * s + 1],
                               substeps=s, n_samples=length, bound=err.bound)
                out.append(sim.states[:, 1] - q2[a:a + length])
        return float(np.mean(np.concatenate(out) ** 2) / np.var(q2[rows]))


def part_criteria(st: Setup, emit) -> None:
    held_rows, amp_rows = st.rows(st.held), st.rows(st.amp_held)
    crit = {"heldout_interleaved": FreeRunError(st.sig, held_rows, model=st.ident.model_),
            "top10pct_abs_q2_rows": FreeRunError(st.sig, st.top10_rows, model=st.ident.model_),
            "all_rows": FreeRunError(st.sig, None, model=st.ident.model_),
            "heldout_highest_blocks": FreeRunError(st.sig, amp_rows, model=st.ident.model_)}
    emit({"amplitudes_v": st.peaks})
    for label in ("chosen", "hand-picked", "q1^3,q1^2*q2", "equation-error"):
        terms = SETS[label]
        c0 = time.process_time()
        m = st.refit(terms, ~st.held, ~held_rows, ftol=1e-4)  # as the budget ranks its candidates
        costs = {k: c.cost(m) for k, c in crit.items() if k != "heldout_highest_blocks"}
        out = {"fit": "interleaved fit rows", **costs,
               **{f"multiple_shooting_{n}": st.multiple_shooting(m, held_rows, n) for n in (64, 256, 1024)},
               "test_mv": st.test(m)}
        emit({label: out})
        m = st.refit(terms, ~st.amp_held, ~amp_rows, ftol=1e-4)
        emit({label: {"fit": "40 lowest-peak blocks", "heldout_highest_blocks": crit["heldout_highest_blocks"].cost(m),
                      "test_mv": st.test(m)}})
        m = st.refit(terms, st.everything, None)
        emit({label: {"fit": "all rows", "all_rows": crit["all_rows"].cost(m), "test_mv": st.test(m),
                      "cpu_s": round(time.process_time() - c0, 1)}})


def part_refits(st: Setup, emit) -> None:
    for label in ("chosen", "hand-picked"):
        emit({label: {"fit": "rows with |q2| above its median",
                      "test_mv": st.test(st.refit(SETS[label], st.everything, st.upper_half_rows))}})
    emit({"6 Duffing prior": {"fit": "interleaved fit rows",
                              "test_mv": st.test(st.refit(SETS["6 Duffing prior"], ~st.held, st.rows(~st.held)))}})
    for label in ("6 Duffing prior", "8 both dampings"):
        emit({label: {"fit": "all rows", "test_mv": st.test(st.refit(SETS[label], st.everything, None))}})


def part_wide(st: Setup, emit) -> None:
    held_rows = st.rows(st.held)
    c0 = time.process_time()
    ch = choose_budget(st.ident.model_, st.names, np.ones(len(st.names), dtype=bool), 7,
                       st.gram.equations(~st.held), st.sig, ~held_rows, held_rows)
    emit({"whole library": {"terms": list(ch.model.equations["q1_dot"]), "cpu_s": round(time.process_time() - c0, 1),
                            "test_mv": st.test(ch.model),
                            "ranking": [(c["terms"], c["refit"]) for c in ch.candidates[:3]]}})


def part_output_error(st: Setup, emit) -> None:
    """The free-run budget with the output's (q2's) error alone screening, refitting and ranking: the
    test sets' own measure, where the default sums q2's and q1's; the winner refit on the fit rows, then
    on all estimation rows (budget_refit="all")."""
    held_rows = st.rows(st.held)
    for label, final in (("fit rows", None), ("all rows", np.ones_like(held_rows))):
        c0 = time.process_time()
        ch = choose_budget(st.ident.model_, st.names, st.ident.selections_["q1_dot"].support, 7,
                           st.gram.equations(~st.held), st.sig, ~held_rows, held_rows, final_rows=final,
                           signals=("q2",))
        emit({f"output error, winner refit on the {label}": {
            "terms": list(ch.model.equations["q1_dot"]), "cpu_s": round(time.process_time() - c0, 1),
            "test_mv": st.test(ch.model), "ranking": [(c["terms"], c["refit"]) for c in ch.candidates[:3]]}})


def part_second_record(st: Setup, emit) -> None:
    """The distribution's second record (data/silverbox/Schroeder80mV.mat, higher output peaks, no test set
    in it) in two roles: ranking the budget's 8 refit candidates (each refit on the estimation range's fit
    rows, as the budget refits them) by their free-run error on it, and as further estimation data (the
    rivals refit on the pooled free-run error of both records' fit rows, identify.simulation.refine)."""
    from identify.chain.states import reconstruct_states
    from identify.simulation.refine import free_run_error

    second = read_recording(bench.SECOND_RECORD, "force", "V1", "V2", fs_hz=bench.FS_HZ)
    sig2 = reconstruct_states(second, st.sig.band_hz)
    edges2, held2 = holdout_blocks(sig2)
    held_rows, held_rows2 = st.rows(st.held), np.repeat(held2, np.diff(edges2))
    ch = choose_budget(st.ident.model_, st.names, st.ident.selections_["q1_dot"].support, 7,
                       st.gram.equations(~st.held), st.sig, ~held_rows, held_rows)
    for cand in [c for c in ch.candidates if c["refit"] is not None]:  # the 8 the budget refit and ranked
        m = st.refit(cand["terms"], ~st.held, ~held_rows, ftol=1e-4)
        emit({"ranked on the second record": cand["terms"],
              "second_record_q2_q1": FreeRunError(sig2, None, model=m).cost(m),
              "second_record_q2": FreeRunError(sig2, None, ("q2",), model=m).cost(m),
              "estimation_heldout": FreeRunError(st.sig, held_rows, model=m).cost(m), "test_mv": st.test(m)})
    for label in ("chosen", "hand-picked"):
        start = st.refit(SETS[label], ~st.held, ~held_rows, ftol=1e-4)
        m, info = refine_free_run(start, [st.sig, sig2], [~held_rows, ~held_rows2])
        pooled = free_run_error([st.sig, sig2], [held_rows, held_rows2], model=m)
        emit({label: {"fit": "both records' fit rows, pooled", "pooled_heldout": pooled.cost(m),
                      "test_mv": st.test(m)}})


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", default=str(Path(__file__).resolve().parents[1] / "data/silverbox/SNLS80mV.mat"))
    p.add_argument("--part", choices=("criteria", "refits", "wide", "output-error", "second-record"),
                   default="criteria")
    args = p.parse_args(argv)
    st = Setup(args.data)
    {"criteria": part_criteria, "refits": part_refits, "wide": part_wide, "output-error": part_output_error,
     "second-record": part_second_record}[args.part](st, lambda d: print(json.dumps(d), flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
