"""A candidate explanation as a model structure, and its fit: equation error first, then multiple shooting.

A Structure is the baseline's terms plus the effects added so far: plain terms, an end-stop travel,
a Bouc-Wen state, a time ramp input, and measurement-fault parameters. The Fitter turns one into
(1) the states it implies (the channels corrected for the faults; the hysteresis state integrated from
the measured velocity), (2) coefficients by least squares on band-limited columns of the training
blocks, with the block-robust covariance, (3) a SparseModel, and (4) its per-segment multiple-shooting
error (identify.simulation.shooting), and can refit the coefficients on the shooting error of the training segments.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares as nl_least_squares

from ..chain.states import StateSignals, spectral_op
from ..regression.gram import BlockGram, sandwich_covariance
from ..regression.library import Library
from .measurement import ZERO, ChannelChain
from ..model import SparseModel
from ..regression.optimizers.base import least_squares
from ..data.recording import Recording
from ..simulation.shooting import FINE_GRID_BYTES, ShootingData, segment_edges
from ..simulation.simulate import fine_grid_input, simulate
from ..threads import map_runs

#: The gap is measured on what was measured: the relative acceleration for the accelerometer rig, the
#: output y itself for a force-input layout (its second derivative is a noise-amplified derived signal).
GAP_SIGNAL = {"base": "q1_dot", "force": "q2"}
#: The shooting refit's smallest Bouc-Wen saturation, per parameter: beta and gamma
#: are each capped at 1 / (this x the largest |q2|). A z saturating within 2 % of the stroke is a Coulomb
#: friction (sign(q1) times its level), which the catalog has; and it is stiff: on a rig without
#: hysteresis a refit drove beta to where the RK4 needed 158-256 substeps a sample (benchmark seed
#: 1706589829, case 141: 122 s of CPU, 5.5 GB of fine inputs before shooting.FINE_GRID_BYTES; measured
#: under STEP_OMEGA on every eigenvalue: STEP_DECAY now takes ~5x fewer for that real mode).
#: The candidate's grid starts at 0.1 (identify.explain.effects.hysteresis.HYST_SATURATION).
HYST_MIN_SATURATION = 0.02
#: RK4 steps per sample of the Bouc-Wen state's integration from the measured velocity (Fitter.z_state).
Z_SUBSTEPS = 2
#: Band-limited library columns kept between equation fits (Fitter.band_limited_columns): the baseline's and
#: the round's terms are the same for every candidate, each a band operation over the whole record.
BAND_LIMITED_CACHE = 32
#: An end stop's asymmetry term and the symmetric term it follows on a one-sided stop: on the stop's
#: side s, f + s sign(q2) f = 2 f there and 0 on the other side.
ONE_SIDED = {"sign(q2)*stop(q2)": "stop(q2)", "q1*sign(q2)*contact(q2)": "q1*contact(q2)"}
#: A candidate's shooting refit (Rounds' and the masking check's) stops once a step the trust region
#: trusts (scipy's `ftol` test: the step gained over a quarter of what its local model predicted) lowers
#: the training segments' squared error by less than this share of itself. The candidates are compared in
#: percents (one closes >= 20 %), and past this their refits crept: a 10-term refit spent 90 of its 102
#: simulations gaining 0.2 % (benchmark seed 3308776133, case 138).
CANDIDATE_REFIT_FTOL = 1e-3
#: Every other refit (the baseline's, the explanation's polish) runs to convergence: scipy's default. The
#: next round starts from what they leave: stopped at CANDIDATE_REFIT_FTOL, a Coulomb explanation's polish
#: halted after a step gaining 1e-4 where its next 16 evaluations took 5.5 % off, and the round after it
#: named a stiffness drift the rig does not have for what was left (benchmark seed 2602334400, case 11;
#: tests/identify/test_explain_later_rounds.py::test_a_later_round_starts_from_the_explanation).
CONVERGED_FTOL = 1e-8


@dataclass(frozen=True)
class Structure:
    terms: tuple[str, ...]                  # dq1/dt terms (canonical names), the input included
    meas: tuple = tuple(sorted(ZERO.items()))  # fault parameters (identify.explain.measurement.PARAMS)
    travel: float | None = None             # end-stop travel (m)
    hyst: tuple[float, float] | None = None  # Bouc-Wen (beta, gamma) in 1/m
    coef: tuple = ()                        # ((term, dq1/dt coefficient), ...)
    effects: tuple[str, ...] = ()           # catalog names added to the baseline, in order
    #: a one-sided end stop: +1 upper, -1 lower (None: two sided). Its asymmetry terms are tied to the
    #: symmetric ones, coef(sign(q2)*f) = side x coef(f), so the stop acts on that side only.
    side: int | None = None
    #: the end-stop travel is refit with the coefficients (identify.explain.effects.end_stop sets it when it adds
    #: the stop; adding any later effect clears it)
    travel_free: bool = False

    @property
    def ties(self) -> dict:
        """{tied term: (free term, factor)}: coefficients that follow another's."""
        if self.side is None:
            return {}
        return {t: (f, float(self.side)) for t, f in ONE_SIDED.items() if t in self.terms and f in self.terms}

    @property
    def p(self) -> dict:
        return dict(self.meas)

    @property
    def coefficients(self) -> dict:
        return dict(self.coef)

    def adding(self, name: str, terms=(), **kw) -> "Structure":
        new = tuple(self.terms) + tuple(t for t in terms if t not in self.terms)
        kw.setdefault("travel_free", False)
        return replace(self, terms=new, effects=self.effects + (name,), **kw)


@dataclass
class Fit:
    """Equation-error fit of a structure: coefficients, standard errors, held-out equation-error MSE."""

    coef: dict
    se: dict
    cov: np.ndarray
    names: list
    mse_heldout: float


@dataclass
class Part:
    """One recording in the fit: its chain's signals, its own blocks (edges over its valid rows) and
    held-out ones, its channel chain (base layout), its drift time tau, and where its valid rows start
    among the pooled rows."""

    rec: Recording
    sig: StateSignals
    edges: np.ndarray
    held: np.ndarray
    chain: ChannelChain | None
    tau: np.ndarray
    offset: int

    @property
    def n(self) -> int:
        return self.sig.valid.stop - self.sig.valid.start


class Fitter:
    """Fits structures over one recording or several of the same rig (same layout, input and sampling
    rate), pooled: each recording keeps its own chain, states, blocks and shooting segments (none crosses
    from one recording into the next), its rows follow the previous recording's; the equation error sums
    the blocks of all, the shooting error is per segment of all, and the coefficients (and fault
    parameters) are one set. A single recording is the list of one.

    The drift time tau runs over each recording (t/T - 1/2 of its own length), not over the campaign: a
    recording carries no clock the others share, a rig rests (and cools) between recordings, and the
    catalog's drift is k (1 + r t/T) over a record, so its rate means the same over one recording or
    several; what several recordings add is sweeps in both directions, over which a drift keeps its
    sign in time while a frequency-dependent stiffness flips."""

    def __init__(self, parts: list[tuple[Recording, StateSignals, np.ndarray, np.ndarray]]):
        self.parts: list[Part] = []
        offset = 0
        for rec, sig, edges, held in parts:
            v = sig.valid
            n = rec.n_samples
            chain = ChannelChain(rec, sig) if rec.layout == "base" else None
            self.parts.append(Part(rec, sig, np.asarray(edges), np.asarray(held), chain,
                                   (np.arange(n) / max(n - 1, 1) - 0.5)[v], offset))
            offset += v.stop - v.start
        first = self.parts[0]
        self.rec, self.sig0 = first.rec, first.sig
        #: block edges and held-out flags over the pooled valid rows
        self.edges = np.concatenate([first.edges] + [p.edges[1:] + p.offset for p in self.parts[1:]])
        self.held = np.concatenate([p.held for p in self.parts])
        self.cuts = tuple(p.offset for p in self.parts[1:])
        self.layout = first.rec.layout
        self.gap = GAP_SIGNAL[self.layout]
        self.u_name = first.sig.input_name
        self.fs_hz = first.sig.fs_hz
        self.chain = first.chain  # None for a force layout (no channel faults)
        self.tau = np.concatenate([p.tau for p in self.parts])
        self.rows_held = np.repeat(self.held, np.diff(self.edges))
        self._z: dict = {}
        self._z_input: dict = {}  # per recording (the id of its own signals, which live as long as the
        # fitter), the z integration's input on its h/2 grid
        self._data: dict = {}
        self._columns: dict = {}  # band_limited_columns' columns, insertion ordered (oldest evicted)
        self._columns_lock = threading.Lock()  # its eviction iterates it: one thread at a time
        #: what an effect computes once per analysis from the recordings alone, by the effect's own key
        #: (mains hum's evidence: the same in every round)
        self.memo: dict = {}
        self.starts = self.stops = self.seg_held = None

    # -- signals ----------------------------------------------------------------------------------
    def signals(self, st: Structure) -> list[StateSignals]:
        """Each recording's signals, corrected for the structure's fault parameters."""
        p = st.p
        if self.chain is None or not any(p.values()):
            return [part.sig for part in self.parts]
        return [part.chain.signals(p) for part in self.parts]

    def pooled(self, sigs: list[StateSignals], name: str) -> np.ndarray:
        """A signal of every recording on its valid rows, one after another."""
        return np.concatenate([getattr(s, name)[s.valid] for s in sigs])

    def displacement(self, st: Structure) -> np.ndarray:
        """The displacement q2 on the pooled valid rows (the range an end stop or hysteresis searches)."""
        return self.pooled(self.signals(st), "q2")

    def z_state(self, sig: StateSignals, hyst) -> np.ndarray:
        """Bouc-Wen state integrated from the measured velocity (valid rows), z(0) = 0."""
        key = (id(sig), hyst)  # the cache holds sig itself, so its id cannot be reused while cached
        hit = self._z.get(key)  # shared by map_runs' threads: .get, and the local returned
        if hit is None:
            beta, gamma = hyst
            q1 = sig.q1[sig.valid]
            zm = SparseModel({"z_dot": {"v": 1.0, "av*z": -beta, "v*|z|": -gamma}}, states=("z",), inputs=("v", "av"))
            scale = float(np.max(np.abs(q1))) / max(beta + gamma, 1e-9) + 1e-9
            # the input (v, |v|) on the h/2 grid is the same for every pair a search tries: made once per
            # recording (a fault's trial corrections, new signals every trial, make their own)
            fine = self._z_input.get(id(sig))
            if fine is None:
                fine = fine_grid_input(np.column_stack([q1, np.abs(q1)]), Z_SUBSTEPS, "linear")
                if any(sig is p.sig for p in self.parts) and fine.nbytes <= FINE_GRID_BYTES:  # as the runs' own
                    self._z_input[id(sig)] = fine
            res = simulate(zm, 1.0 / sig.fs_hz, [0.0], inputs_fine=fine, substeps=Z_SUBSTEPS, n_samples=q1.size,
                           bound=1e3 * scale)
            if len(self._z) > 64:
                self._z.clear()
            hit = self._z[key] = (sig, np.nan_to_num(res.states[:, 0]))
        return hit[1]

    def names(self, st: Structure):
        states = ("q1", "q2", "z") if st.hyst is not None else ("q1", "q2")
        inputs = (self.u_name, "tau") if any("tau" in t for t in st.terms) else (self.u_name,)
        return states, inputs

    def arrays(self, st: Structure, sigs: list[StateSignals] | None = None):
        """(states (n, k), inputs (n, m)) on the pooled valid rows."""
        sigs = sigs or self.signals(st)
        drift = any("tau" in t for t in st.terms)
        cols = [self.pooled(sigs, "q1"), self.pooled(sigs, "q2")]
        if st.hyst is not None:
            cols.append(np.concatenate([self.z_state(s, st.hyst) for s in sigs]))
        ins = [self.pooled(sigs, "input")] + ([self.tau] if drift else [])
        return np.column_stack(cols), np.column_stack(ins)

    def library(self, st: Structure) -> Library:
        states, inputs = self.names(st)
        return Library.from_terms(st.terms, states=states, inputs=inputs,
                                  travel={"q2": st.travel} if st.travel else None)

    # -- equation error ---------------------------------------------------------------------------
    def equation_fit(self, st: Structure, band_limited: bool = True) -> Fit:
        sigs = self.signals(st)
        lib = self.library(st)
        T = self.tie_matrix(st, lib.names)  # all coefficients = T @ the free ones
        # the free columns and the target q1_dot side by side, made in place (a record-sized array per fit:
        # stacking, tying and appending the target had copied it three more times)
        target = self.pooled(sigs, "q1_dot")
        M = np.empty((target.size, T.shape[1] + 1))
        if band_limited:  # each recording's columns through its own band, over its whole record
            for s, p in zip(sigs, self.parts):
                self.band_limited_columns(lib, T, st, s, p, out=M[p.offset:p.offset + p.n, :-1])
        else:
            X, U = self.arrays(st, sigs)
            M[:, :-1] = lib.evaluate(X, U) @ T
        M[:, -1] = target
        gram = BlockGram(M, 1, self.edges)
        train, heldout = gram.equations(~self.held), gram.equations(self.held)
        support = np.ones(T.shape[1], bool)
        x = least_squares(train.G, train.B[:, 0], support)
        S = np.arange(T.shape[1])
        cov = T @ sandwich_covariance(gram, ~self.held, train.G, S, x, 0) @ T.T
        mse = float(heldout.mse(x[:, None], 0)[0])
        x = T @ x
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        return Fit(dict(zip(lib.names, map(float, x))), dict(zip(lib.names, map(float, se))), cov, lib.names, mse)

    def band_limited_columns(self, lib: Library, T: np.ndarray, st: Structure, sig: StateSignals, part: Part,
                             out: np.ndarray):
        """The library's columns of one recording through its chain's band, on its valid rows, tied (@ T)
        and written into `out` (valid rows, free terms), which is returned. The columns are built over
        the whole record, as the chain built the target q1_dot from the whole raw record: cut to the valid
        rows first, a record loud at the edge of its valid rows (a down-sweep starting at its top
        frequency) rang through the band (with the true coefficients: a band-limited residual of 10
        (m/s^2)^2 over the first eighth of a 20-1 Hz down-sweep, 2e-5 built whole). The hysteresis state,
        integrated over the valid rows from z = 0, is 0 before them and held after."""
        # only the recording's own signals are kept (a fault candidate's corrected ones are new every trial)
        keep = sig is part.sig
        keys = [self._column_key(t, st, part) for t in lib.terms]
        # read once, each key: the rounds' proposals run in threads (identify.threads.map_runs) and evict
        cached = [self._columns.get(k) if keep else None for k in keys]
        missing = [j for j, c in enumerate(cached) if c is None]
        fresh = {}
        if missing:
            n, v = part.rec.n_samples, sig.valid
            cols = [sig.q1, sig.q2]
            if st.hyst is not None:
                z = self.z_state(sig, st.hyst)
                cols.append(np.concatenate([np.zeros(v.start), z, np.full(n - v.stop, z[-1] if z.size else 0.0)]))
            drift = any("tau" in t for t in st.terms)
            ins = [sig.input] + ([np.arange(n) / max(n - 1, 1) - 0.5] if drift else [])
            A = lib.subset(missing).evaluate(np.column_stack(cols), np.column_stack(ins))
            for j, c in zip(missing, A.T):
                fresh[j] = spectral_op(c, sig.fs_hz, sig.band_hz, 0, sig.taper_n)[v]
        columns = [fresh[j] if j in fresh else c for j, c in enumerate(cached)]
        if T.shape[0] == T.shape[1] and np.array_equal(T, np.eye(T.shape[0])):
            for j, c in enumerate(columns):  # no ties: the columns themselves (what @ T gives, without a product)
                out[:, j] = c
        else:
            out[...] = np.column_stack(columns) @ T
        if keep:
            with self._columns_lock:
                self._columns.update((keys[j], c) for j, c in fresh.items())
                while len(self._columns) > BAND_LIMITED_CACHE:
                    self._columns.pop(next(iter(self._columns)))  # the oldest first
        return out

    @staticmethod
    def _column_key(term, st: Structure, part: Part) -> tuple:
        """What a band-limited column of the recording's own signals depends on: the recording, the term,
        the Bouc-Wen pair if it reads z, the travel if it has a stop or contact."""
        features = [f for f, _ in term.factors]
        reads_z = any(f.strip("|") == "z" or f.endswith("(z)") for f in features)
        stop = any(f.startswith(("stop(", "contact(")) for f in features)
        return (part.offset, term.name, st.hyst if reads_z else None, st.travel if stop else None)

    @staticmethod
    def tie_matrix(st: Structure, names) -> np.ndarray:
        """(all terms, free terms) matrix mapping the free coefficients to every term's (Structure.ties)."""
        ties = st.ties
        free = [t for t in names if t not in ties]
        T = np.zeros((len(names), len(free)))
        for i, t in enumerate(names):
            src, factor = ties.get(t, (t, 1.0))
            T[i, free.index(src)] = factor
        return T

    # -- models and the shooting error ------------------------------------------------------------
    def model(self, st: Structure, coef: dict | None = None) -> SparseModel:
        coef = st.coefficients if coef is None else coef
        states, inputs = self.names(st)
        eqs = {"q1_dot": dict(coef), "q2_dot": {"q1": 1.0}}
        if st.hyst is not None:
            beta, gamma = st.hyst
            eqs["z_dot"] = {"q1": 1.0, "|q1|*z": -beta, "q1*|z|": -gamma}
        return SparseModel(eqs, states=states, inputs=inputs, travel={"q2": st.travel} if st.travel else None)

    def set_segments(self, f_res_hz: float) -> None:
        self.starts, self.stops, self.seg_held = segment_edges(self.edges, self.held, self.fs_hz, f_res_hz)

    def lowpass(self, x: np.ndarray) -> np.ndarray:
        """A simulated signal through each recording's band top (contacts ring above it)."""
        return np.concatenate([spectral_op(x[p.offset:p.offset + p.n], p.sig.fs_hz, (0.0, p.sig.band_hz[1]), 0, 0)
                               for p in self.parts])

    def data(self, st: Structure, starts=None, stops=None) -> ShootingData:
        key = (st.meas, st.hyst, any("tau" in t for t in st.terms), starts is None)
        hit = self._data.get(key)  # shared by map_runs' threads: .get, not `in` then [ ]
        if hit is not None:
            return hit
        sigs = self.signals(st)
        X, U = self.arrays(st, sigs)
        measured = self.pooled(sigs, "q1_dot" if self.gap == "q1_dot" else "q2")
        s0 = self.starts if starts is None else np.asarray(starts)
        s1 = self.stops if stops is None else np.asarray(stops)
        held = self.seg_held if starts is None else np.zeros(len(s0), bool)
        d = ShootingData(X, U, measured, self.gap, self.fs_hz, s0, s1, held, 1.0 + st.p.get("mass_acc_gain", 0.0),
                         self.lowpass, self.cuts)
        if len(self._data) > 16:  # each holds up to shooting.FINE_GRID_BYTES of fine inputs
            self._data.clear()  # before inserting: the entry is used right after
        self._data[key] = d
        return d

    def errors(self, st: Structure) -> np.ndarray:
        """Per-segment squared shooting error of the gap signal, in recorded units."""
        return self.data(st).run(self.model(st))[1]

    def unfiltered_runs(self, st: Structure) -> np.ndarray:
        """The structure's multiple-shooting runs (errors' segments) of the gap signal on the pooled valid
        rows, not band-limited (NaN outside the segments): what the model puts above the band, a friction's
        or a contact's force steps among it (the noise floor after an effect: DiscrepancyAnalysis)."""
        return replace(self.data(st), lowpass=None).run(self.model(st))[0]

    def free_run(self, st: Structure):
        """One free run per recording over its valid rows, from its first state: the simulated gap signal
        on the pooled rows (NaN where it diverged)."""
        return self.data(st, [p.offset for p in self.parts], [p.offset + p.n for p in self.parts]).run(self.model(st))[0]

    def part_of(self, row: int) -> Part:
        """The recording a pooled row belongs to."""
        return [p for p in self.parts if p.offset <= row][-1]

    def refine(self, st: Structure, max_nfev: int = 12, ftol: float = CONVERGED_FTOL) -> Structure:
        """Coefficients refit on the training segments' shooting error (trust region, Gauss-Newton); for
        a Bouc-Wen structure (beta, gamma) too, on a log scale (the grid only starts them), the state
        z at each segment start integrated again from the measured velocity for every trial pair; for an
        end stop just added, its travel too (log scale: the grid's step is 6-10 % of the peak, and a
        stiff contact's force is its stiffness times a penetration of that order). It stops after max_nfev
        evaluations or at a trusted step gaining less than ftol of the error (by default CONVERGED_FTOL; the
        candidates' refits: refine_candidate)."""
        ties = st.ties
        names = [t for t in st.coefficients if t not in ties]  # tied terms follow their free term
        theta0 = np.array([st.coefficients[t] for t in names])
        k = len(names)
        hyst = st.hyst is not None
        travel = bool(st.travel) and st.travel_free
        extra = (list(np.log(np.maximum(st.hyst, 1e-3))) if hyst else []) + ([np.log(st.travel)] if travel else [])
        theta0 = np.concatenate([theta0, extra])
        train = ~self.seg_held
        norm = float(np.sqrt(np.sum(self.data(st).measured ** 2))) or 1.0
        # beta, gamma capped where z would saturate below HYST_MIN_SATURATION of the stroke (flat beyond)
        log_cap = -np.log(HYST_MIN_SATURATION * float(np.max(np.abs(self.displacement(st))))) if hyst else 0.0

        def build(theta) -> Structure:
            coef = dict(zip(names, map(float, theta[:k])))
            coef.update({t: factor * coef[src] for t, (src, factor) in ties.items()})
            out = replace(st, coef=tuple((t, coef[t]) for t in st.coefficients))
            if hyst:
                out = replace(out, hyst=tuple(map(float, np.exp(np.minimum(theta[k:k + 2], log_cap)))))
            return replace(out, travel=float(np.exp(theta[-1]))) if travel else out

        def resid(theta):
            cand = build(theta)
            return self.data(cand).residuals(self.model(cand), train) / norm

        r0 = resid(theta0)
        scale = np.maximum(np.abs(theta0), 1e-12)
        scale[k:] = 1.0
        sol = nl_least_squares(resid, theta0, x_scale=scale, diff_step=1e-6, max_nfev=max_nfev, ftol=ftol,
                               method="trf", workers=map_runs)  # the Jacobian's columns side by side, numbers as serial
        if not (np.all(np.isfinite(sol.x)) and 2 * sol.cost < float(r0 @ r0)):
            return st
        return build(sol.x)

    def refine_candidate(self, st: Structure) -> Structure:
        """A candidate's refit (a round's, the masking check's): refine, stopped at CANDIDATE_REFIT_FTOL."""
        return self.refine(st, ftol=CANDIDATE_REFIT_FTOL)
