"""Identification speed end to end, next to its anchors, in one process so the ratios hold on a busy machine.

    python benchmarks/identify_speed.py [--sizes 1000000] [--repeat 3] [--busy 0 1] [--no-cli] [--no-pysindy]
        [--no-simulation] [--validation-parts] [--uncertainty-parts] [--seed S]

Runs in the user's default environment: BLAS as installed (OpenBLAS starts one thread per core; the
identification limits itself, identify.threads), scipy.fft's default one worker. Each --busy level N
runs the whole measurement with N processes spinning `while True: pass` beside it (default: 0, then 1);
the load average and BLAS threads are printed with each block, so an "idle" block on a machine others
load says so.

Recording: the paper's Table 1 rig, a 1-20 Hz sweep at 1.2 mm over n / 2048 Hz - 2 s plus 2 s at rest,
two accelerometers at 0.5 % noise (sim.synth.run_sweep), fresh noise every run: the seed is printed
(--seed repeats one). At 1.2 mm the slow sweep's resonance peaks at 15.4 mm (n = 1e6), clear of the
17.5 mm end stops; at 1.3 mm it jumps onto them.

For each record length n, timed in rounds (anchor, then each call once per round; best of --repeat):
  anchor "one pass over the data": the 16-column library (freshly allocated) + A.T@A + one rfft/irfft
      pair at next_fast_len(n) per recorded channel (table and mass acceleration);
  shakeid, the public call: SparseIdentifier(validate=False).fit(recording) and SparseIdentifier().fit
      (with the free-run validation), and its parts (SparseIdentifier.timings_: chain, library and Gram,
      path, selection and refit, uncertainty, validation); both also without the uncertainty step
      (bias_replicates=0, placements=0), whose cost does not depend on the rest;
  the CLI (largest n): `shakeid identify FILE.mat --json` as a process, default threads and
      OPENBLAS_NUM_THREADS=1 in alternating rounds (user CPU), `import shakeid.cli` alone, and the
      call's parts from its JSON;
  PySINDy at equal quality (largest n, first --busy level): given shakeid's chain states (its own
      trapezoidal integration recovers no support), SINDy.fit with the same 16 columns, STLSQ on
      normalized columns at the first threshold that recovers the true support (speedkit.py).
Targets (issue 30): fit <= 1.5x the anchor, fit with validation <= 2.5x, idle and with one busy process;
the CLI's user CPU with default threads within 1.3x of one thread under load. Each figure is given as
wall time and as the process's CPU time. Every timed call starts with shakeid's twiddle cache empty
(identify.chain.spectral), so a repeat of the same record pays what a user's first call on a new recording
does; scipy's own FFT plan cache, which cannot be cleared, is warm for the anchor and the calls alike.

Then free-run simulation of a 60 s sweep against scipy solve_ivp (RK45, rtol 1e-8) at equal accuracy:
both integrate the same cubic-spline input; the error of each is measured against DOP853 at rtol 1e-12,
and shakeid runs with the fewest substeps that are at least as accurate as RK45. Target >= 100x.
Needs the bench extras: pip install -e '.[bench]'.
"""
from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import speedkit  # noqa: E402

from identify.chain.states import reconstruct_states  # noqa: E402
from identify.identifier import SparseIdentifier  # noqa: E402
from identify.regression.library import Library  # noqa: E402
from identify.model import SparseModel  # noqa: E402
from identify.simulation.simulate import simulate  # noqa: E402
from identify.chain.spectral import _cached_twiddles  # noqa: E402
from identify.threads import one_blas_thread  # noqa: E402
from identify.trust.uncertainty import N_PLACEMENTS  # noqa: E402
from sim.rig import RigParameters  # noqa: E402
from protocol.sweep import SineSweep  # noqa: E402
from sim.synth import run_sweep  # noqa: E402

FS = 2048.0
AMPLITUDE_MM = 1.2
TARGETS = {"fit": 1.5, "fit_validated": 2.5, "cli_threads": 1.3}
PARTS = ("chain", "library_gram", "path", "selection_refit", "offset", "refit_uncertainty", "validation")


def timed(fn):
    """(wall seconds, CPU seconds of this process), result; shakeid's twiddle cache emptied first (a
    repeat on the same record would otherwise skip work a new recording needs)."""
    _cached_twiddles.cache_clear()
    gc.collect()
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return (time.perf_counter() - t0, time.process_time() - c0), out


def best_of(fn, repeat):
    """Best wall and best CPU time of `repeat` runs (as (wall, cpu)), and the last result."""
    times, out = [], None
    for _ in range(repeat):
        t, out = timed(fn)
        times.append(t)
    return (min(t[0] for t in times), min(t[1] for t in times)), out


def sweep_recording(n: int, seed: int | None = None):
    """The benchmark's recording of n samples; its sensor noise drawn from `seed` (None: fresh)."""
    run = run_sweep(sweep=SineSweep(1.0, 20.0, n / FS - 2.0, AMPLITUDE_MM), settle_s=2.0, seed=seed)
    return run.recording.slice(0, n), run.truth


def anchor(rec, lib, X, U) -> dict:
    """One pass over the data: what any identification of this record must at least do.
    Each entry (wall, cpu) seconds."""
    out = {}
    out["library"], A = timed(lambda: lib.evaluate(X, U))
    out["gram"], _ = timed(lambda: A.T @ A)
    m = next_fast_len(rec.n_samples, real=True)
    out["fft_pairs"], _ = timed(lambda: [irfft(rfft(ch, m), m) for ch in (rec.input, rec.output)])
    out["total"] = tuple(sum(out[k][i] for k in ("library", "gram", "fft_pairs")) for i in range(2))
    return out


@one_blas_thread  # parts timed alone run as they run inside the fit (identify.threads)
def chain_transforms(rec, sig) -> dict:
    """The chain's transforms alone, each (wall, cpu) seconds: 2 forward (qdd and the input, each without
    its mean: identify.chain.states.by_mean_alone) and 4 inverse (q1, q2, q1_dot, input) rffts, zero-padded as
    the chain pads (identify.chain.states.padded_length), limited to the band's bins and in the precision the
    chain does them (identify.chain.spectral, identify.chain.states.STATE_DTYPE), and the two Welch spectra of the band
    estimate (16384-sample segments, transformed in single precision as identify.chain.band.excited_band does)."""
    from identify.chain.states import STATE_DTYPE, band_gain, padded_length
    from identify.chain.spectral import lowband_irfft, lowband_rfft, welch_psd

    n = rec.n_samples
    m = padded_length(n, rec.fs_hz, sig.band_hz)
    k_max = int(np.flatnonzero(band_gain(np.fft.rfftfreq(m, rec.dt), sig.band_hz, rec.fs_hz))[-1])
    rows = np.vstack([rec.output - rec.input, rec.input])
    out = {}
    t_fwd, spec = timed(lambda: lowband_rfft(rows, m, k_max, STATE_DTYPE))
    t_inv, _ = timed(lambda: lowband_irfft(np.vstack([spec, spec]), m, n))
    out["padded_ffts"] = tuple(a + b for a, b in zip(t_fwd, t_inv))
    out["welch"], _ = timed(lambda: [welch_psd(x, rec.fs_hz, 16384, np.float32) for x in (rec.input, rows[0])])
    return out


def identification_figures(n: int, repeat: int, seed: int, pysindy: bool = False, cli: bool = False) -> dict:
    """Anchor, the public call and its parts in rounds on a recording of n samples with noise from `seed`;
    with cli, the CLI on the same recording written to a .mat file; with pysindy, PySINDy at equal quality."""
    rec, truth = sweep_recording(n, seed)
    sig = reconstruct_states(rec)  # states for the anchor's library (not timed)
    X, U = (sig.q1, sig.q2), sig.input[:, None]
    lib = Library()
    f = {"n": n, "peak_mm": 1e3 * truth["max_abs_q_m"], "contact_samples": truth["contact_samples"]}
    runs = {"anchor": [], "transforms": [], "fit": [], "fit_validated": [], "fit_no_uncertainty": [],
            "validated_no_uncertainty": []}
    for _ in range(repeat):  # rounds: a load spike on the machine hits anchor and calls alike
        runs["anchor"].append(anchor(rec, lib, X, U))
        runs["transforms"].append(chain_transforms(rec, sig))
        for key, kw in (("fit", dict(validate=False)), ("fit_validated", {}),
                        ("fit_no_uncertainty", dict(validate=False, bias_replicates=0, placements=0)),
                        ("validated_no_uncertainty", dict(bias_replicates=0, placements=0))):
            t, ident = timed(lambda kw=kw: SparseIdentifier(**kw).fit(rec))
            runs[key].append({"total": t, "parts": dict(ident.timings_), "model": ident.model_,
                              "verdict": ident.verdict_["status"]})
    tr = runs.pop("transforms")
    f["transforms"] = {k: (min(r[k][0] for r in tr), min(r[k][1] for r in tr)) for k in tr[0]}
    for key, rs in runs.items():  # best wall and best CPU time; parts (wall) of the fastest run
        f[key] = dict(min(rs, key=lambda r: r["total"][0]))
        f[key]["total"] = (min(r["total"][0] for r in rs), min(r["total"][1] for r in rs))
    if cli:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "sweep.mat"
            speedkit.write_mat(path, rec)
            f["cli"] = speedkit.cli_figures(path, repeat)
    if pysindy:
        f["pysindy"] = speedkit.pysindy_equal_quality(sig)
    return f


@one_blas_thread  # parts timed alone run as they run inside the fit (identify.threads)
def validation_parts(n: int, repeat: int, seed: int) -> dict:
    """What the free-run validation of the fitted (training-only) model spends, CPU seconds, best of
    `repeat`: validate() as a whole, and its parts done alone: the input on the RK4 half-step grid (from
    the chain's spectrum, StateSignals.input_fine; what a run in steps of `stride` samples reads), the
    compiled RK4 run on it (with the steps validate takes, identify.simulation.simulate.choose_step; and in steps of
    one sample, for comparison), the simulated displacement through the chain's band with its two
    derivatives (one forward and three inverse single-precision transforms, as validate does them), and
    the fit metrics of the seven pairs (validation.heldout_and_all_metrics)."""
    from identify.simulation.simulate import choose_step
    from identify.simulation.validation import _runs, _runs_of, fit_metrics, heldout_and_all_metrics, validate

    rec, _ = sweep_recording(n, seed)
    ident = SparseIdentifier(validate=False, bias_replicates=0, placements=0).fit(rec)
    sig, model, rows = ident.states_, ident.training_model_, ident.heldout_rows_
    v = sig.valid
    x, u = sig.states[v], sig.input[v][:, None]
    out, sim, qdot = validate(model, sig, rows)
    subs, stride = choose_step(model, 1.0 / sig.fs_hz, 1.5 * np.max(np.abs(x), axis=0))
    assert subs == out["substeps"]
    fine, fine_all = sig.input_fine(subs, stride), sig.input_fine(subs)
    res = simulate(model, 1.0 / sig.fs_hz, x[0], inputs_fine=fine, substeps=subs, n_samples=u.shape[0], bound=1e3,
                   stride=stride)
    runs = _runs(rows)
    held = _runs_of(runs)

    def cpu(fn):
        return best_of(fn, repeat)[0][1]

    return {"rows": u.shape[0], "substeps": subs, "stride": stride, "validate": cpu(lambda: validate(model, sig, rows)),
            "input_grid": cpu(lambda: sig.input_fine(subs, stride)),
            "rk4": cpu(lambda: simulate(model, 1.0 / sig.fs_hz, x[0], inputs_fine=fine, substeps=subs,
                                        n_samples=u.shape[0], bound=1e3, stride=stride)),
            "rk4_one_sample": cpu(lambda: simulate(model, 1.0 / sig.fs_hz, x[0], inputs_fine=fine_all, substeps=subs,
                                                   n_samples=u.shape[0], bound=1e3)),
            "band_limit": cpu(lambda: sig.band_limit_derivatives(res.states[:, 1], (0, 1, 2), np.float32)),
            # as validate scores them: each signal's held-out and all-rows figures from one pass, and the
            # one-step fit of the held-out acceleration
            "metrics": cpu(lambda: [heldout_and_all_metrics(sig.q1[v], sim[:, 0], runs) for _ in range(3)]
                           + [fit_metrics(held(sig.q1[v]), held(sim[:, 0]))])}


@one_blas_thread  # parts timed alone run as they run inside the fit (identify.threads)
def uncertainty_parts(n: int, repeat: int, seed: int) -> dict:
    """What the uncertainty step (identify.trust.uncertainty.assess, as SparseIdentifier runs it) spends on the
    default fit, CPU seconds, best of `repeat`, its parts done alone: the all-rows refits with their
    block-robust covariances, the noise floors (read from the band search's Welch spectra, whose cost is
    the chain's: the figure is the reading alone), the closed-form chain bias as a whole
    (analytic_chain_bias: floors, corrected sums and the noise's share of the variance), the noise's
    share alone (identify.trust.noise_spread), and the inclusion probabilities (24 held-out placements: ADMM
    paths and the selection rule) with, of them, the ADMM paths alone."""
    from identify.trust import uncertainty as unc
    from identify.noise.chain_noise import BandLimitedNoise
    from identify.chain.bias_correction import term_exponents
    from identify.identifier import effective_samples, holdout_blocks
    from identify.trust.noise_spread import noise_variance

    rec, _ = sweep_recording(n, seed)
    ident = SparseIdentifier(validate=False, bias_replicates=0, placements=0).fit(rec)
    sig, lib = ident.states_, ident.library_
    edges, held = holdout_blocks(sig)
    gram = ident._gram(sig, edges)
    sups = {e: s.support for e, s in enumerate(ident.selections_.values())}
    coefs = {e: unc.refit_all_rows(gram, sups[e], e, covariance=False)[0] for e in sups}
    v = sig.valid
    noise = BandLimitedNoise(rec.input.size, sig.fs_hz, sig.band_hz, rec.layout)
    floors = unc.noise_floors(rec, sig.band_hz, sig.spectra)  # from the band search's spectra, as the fit reads them
    parts = [((sig.q1[v], sig.q2[v], sig.q1_dot[v], sig.input[v]), noise, floors)]
    G = gram.equations(np.ones(gram.n_blocks, dtype=bool)).G
    col_exps = [term_exponents(t, sig.input_name) for t in lib.terms]
    opt, n_eff = ident._optimizer(), effective_samples(sig)
    masks = unc.placements(held, unc.N_PLACEMENTS)
    trains = [gram.equations(~m) for m in masks]

    def fit_and_select(trains, heldouts):
        return ident._placement_supports(trains, heldouts, n_eff)

    def cpu(fn):
        return best_of(fn, repeat)[0][1]

    return {"refits": cpu(lambda: [unc.refit_all_rows(gram, sups[e], e) for e in sups]),
            "floors": cpu(lambda: unc.noise_floors(rec, sig.band_hz, sig.spectra)),
            "closed_form": cpu(lambda: unc.analytic_chain_bias(rec, sig, gram, lib, sups, coefs)),
            "noise_share": cpu(lambda: noise_variance(parts, sups, coefs, G, col_exps, unc.TARGET_EXPONENTS)),
            "inclusion": cpu(lambda: unc.inclusion_probabilities(gram, held, fit_and_select)),
            "paths": cpu(lambda: opt.fit_paths(trains, start=ident.path_))}


@one_blas_thread  # parts timed alone run as they run inside the fit (identify.threads)
def padding_lever(n: int, repeat: int, seed: int) -> dict:
    """What the chain's zero padding costs: the chain as it is (PAD_PERIODS periods of f_lo, at most the
    record's length) against the previous rule (always the record's length, 2n in all), CPU time and how
    far the states move (max |difference| / peak on valid rows)."""
    import identify.chain.states as chain

    rec, _ = sweep_recording(n, seed)
    t_cut, cut = best_of(lambda: reconstruct_states(rec), repeat)
    product = chain.PAD_PERIODS
    chain.PAD_PERIODS = 1e12
    try:
        t_ref, ref = best_of(lambda: reconstruct_states(rec), repeat)
    finally:
        chain.PAD_PERIODS = product
    v = ref.valid
    diff = {k: float(np.max(np.abs(getattr(cut, k)[v] - getattr(ref, k)[v])) / np.max(np.abs(getattr(ref, k)[v])))
            for k in ("q1", "q2", "q1_dot", "input")}
    return {"periods": product, "chain_cpu": t_ref[1], "cut_cpu": t_cut[1], "difference": diff}


def simulation_figures(repeat: int) -> dict:
    model = RigParameters.paper_table1().model()
    sweep = SineSweep(1.0, 20.0, 60.0, 1.3)
    n = int(62 * FS)
    t = np.arange(n) / FS
    u = sweep.kinematics(t)[2]
    from scipy.integrate import solve_ivp
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(t, u)  # the input both integrators see (shakeid: interpolation="cubic")
    m = SparseModel(model.equations)

    def rhs(tt, x):
        q1, q2 = x
        return [-3.7294 * q1 - 971.0169 * q2 + 1.162e4 * q1 * q2 * q2 - 2.5033e6 * q2**3 - 1.0243 * spline(tt), q1]

    ref = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-12, atol=1e-15).y[1]
    scale = np.max(np.abs(ref))
    t_ivp, sol = best_of(lambda: solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, method="RK45", rtol=1e-8,
                                           atol=1e-12).y[1], 1)
    err_ivp = float(np.max(np.abs(sol - ref)) / scale)
    out = {"samples": n, "solve_ivp_rk45_s": t_ivp, "solve_ivp_rel_error": err_ivp, "shakeid": []}
    for substeps in (1, 2, 4, 8):
        t_ours, res = best_of(lambda s=substeps: simulate(m, 1 / FS, [0.0, 0.0], u, substeps=s, interpolation="cubic"),
                              repeat)
        err = float(np.max(np.abs(res.states[:, 1] - ref)) / scale)
        out["shakeid"].append({"substeps": substeps, "seconds": t_ours, "rel_error": err})
        if err <= err_ivp:
            out["equal_accuracy"] = {"substeps": substeps, "seconds": t_ours, "speedup": t_ivp[0] / t_ours[0]}
            break
    return out


def _parts(timings: dict) -> str:
    return ", ".join(f"{k} {timings[k]:.3f}" for k in PARTS if k in timings)


def _print_identification(n: int, f: dict) -> None:
    a, fit, val = f["anchor"], f["fit"], f["fit_validated"]
    for i, kind in enumerate(("wall", "cpu")):
        print(f"{n if i == 0 else '':>9} {kind:>5s} {a['total'][i]:8.3f} {fit['total'][i]:8.3f} "
              f"{fit['total'][i] / a['total'][i]:6.2f} {val['total'][i]:8.3f} {val['total'][i] / a['total'][i]:6.2f}",
              flush=True)
    print(f"          anchor (wall/cpu): library {a['library'][0]:.3f}/{a['library'][1]:.3f}, A.T@A "
          f"{a['gram'][0]:.3f}/{a['gram'][1]:.3f}, 2 FFT pairs at next_fast_len(n) "
          f"{a['fft_pairs'][0]:.3f}/{a['fft_pairs'][1]:.3f}")
    tr = f["transforms"]
    print(f"          the chain's transforms (wall/cpu): 2 forward + 4 inverse rfft, padded as the chain pads, band "
          f"bins, single precision {tr['padded_ffts'][0]:.3f}/{tr['padded_ffts'][1]:.3f}, 2 Welch spectra "
          f"{tr['welch'][0]:.3f}/{tr['welch'][1]:.3f} = {(tr['padded_ffts'][1] + tr['welch'][1]) / a['total'][1]:.2f}"
          " x the anchor (cpu)")
    print(f"          fit parts (wall, fastest run): {_parts(fit['parts'])}")
    core, core_val = f["fit_no_uncertainty"], f["validated_no_uncertainty"]
    print(f"          fit without the uncertainty step (bias_replicates=0, placements=0; all-rows refit kept), "
          f"wall/cpu: {core['total'][0]:.3f}/{core['total'][1]:.3f} = {core['total'][1] / a['total'][1]:.2f} x the "
          f"anchor (cpu); with the free-run validation {core_val['total'][0]:.3f}/{core_val['total'][1]:.3f} = "
          f"{core_val['total'][1] / a['total'][1]:.2f} x; validation {core_val['total'][1] - core['total'][1]:.3f} s "
          "CPU by difference")
    print(f"          fit+val parts (wall, fastest run): {_parts(val['parts'])} (verdict {val['verdict']})")
    print(f"          peak |q2| {f['peak_mm']:.1f} mm, {f['contact_samples']} samples on the end stops; "
          f"model: {fit['model']!r}", flush=True)
    if "cli" in f:
        c = f["cli"]
        print(f"          CLI `shakeid identify FILE.mat --json` (best of rounds, wall/user/sys s): default threads "
              f"{c['default']['wall']:.2f}/{c['default']['user']:.2f}/{c['default']['sys']:.2f}, one BLAS thread "
              f"{c['one_thread']['wall']:.2f}/{c['one_thread']['user']:.2f}/{c['one_thread']['sys']:.2f}: user CPU "
              f"default / one thread {c['default']['user'] / c['one_thread']['user']:.2f} (target <= "
              f"{TARGETS['cli_threads']:g}); `import shakeid.cli` alone {c['import']['wall']:.2f}/"
              f"{c['import']['user']:.2f}/{c['import']['sys']:.2f}; its fit parts (wall) "
              + ", ".join(f"{k} {v:.3f}" for k, v in c["parts"].items()) + f" ({c['status']})", flush=True)
    if "pysindy" in f:
        ps_ = f["pysindy"]
        if ps_["threshold"] is None:
            print(f"          PySINDy: no threshold of {[t for t, _ in ps_['tried']]} recovered the true support "
                  f"(terms in the first equation: {[k for _, k in ps_['tried']]})")
        else:
            print(f"          PySINDy at equal quality (given shakeid's chain states; STLSQ threshold "
                  f"{ps_['threshold']:g} x sqrt(rows), normalized columns; thresholds tried {[t for t, _ in ps_['tried']]}): "
                  f"wall/cpu {ps_['time'][0]:.3f}/{ps_['time'][1]:.3f} = {ps_['time'][1] / fit['total'][1]:.1f} x "
                  f"shakeid's whole fit (cpu), {ps_['time'][1] / a['total'][1]:.1f} x the anchor; first equation "
                  + ", ".join(f"{k} {v:.5g}" for k, v in ps_["model"].items()), flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=int, nargs="*", default=[1_000_000])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--busy", type=int, nargs="*", default=[0, 1],
                   help="busy processes beside the measurement, one block per level (default: 0, then 1)")
    p.add_argument("--seed", type=int, default=None, help="the noise's seed (default: fresh, printed)")
    p.add_argument("--no-cli", action="store_true", help="skip timing `shakeid identify` as a process")
    p.add_argument("--no-pysindy", action="store_true", help="skip the PySINDy anchor")
    p.add_argument("--no-simulation", action="store_true", help="skip the free-run vs solve_ivp figures")
    p.add_argument("--validation-parts", action="store_true",
                   help="also time the free-run validation's parts alone (largest size)")
    p.add_argument("--uncertainty-parts", action="store_true",
                   help="also time the uncertainty step's parts alone (largest size)")
    p.add_argument("--padding-lever", action="store_true",
                   help="also time the chain padded to 2n (the previous rule) against its own padding (largest size)")
    args = p.parse_args(argv)
    if not args.no_pysindy:
        try:
            import pysindy  # noqa: F401 - the anchor; checked before minutes of timing, not after
        except ImportError:
            p.error("the PySINDy anchor is not installed: `make bench` installs it (.[bench]), or pass --no-pysindy")
    seed = int(np.random.SeedSequence().entropy % 2**32) if args.seed is None else args.seed
    print(f"seed {seed} (--seed {seed} repeats this run's noise); BLAS as installed: {speedkit.blas_threads()} "
          "thread(s); identify.threads limits its fits to one")
    largest = max(args.sizes) if args.sizes else None
    for level, n_busy in enumerate(args.busy):
        with speedkit.busy(n_busy):
            print(f"\n--- {n_busy} busy process(es) beside; {speedkit.load()} at the start")
            print(f"{'n':>9s} {'time':>5s} {'anchor':>8s} {'fit':>8s} {'ratio':>6s} {'fit+val':>8s} {'ratio':>6s}")
            print(f"{'':9s} {'':5s} {'':8s} {'':8s} {'<=' + format(TARGETS['fit'], 'g'):>6s} {'':8s} "
                  f"{'<=' + format(TARGETS['fit_validated'], 'g'):>6s}   seconds, best of --repeat rounds; "
                  "ratio = call / anchor")
            for k, n in enumerate(args.sizes):
                f = identification_figures(n, args.repeat, seed + 1000 * level + k,
                                           pysindy=not args.no_pysindy and level == 0 and n == largest,
                                           cli=not args.no_cli and n == largest)
                _print_identification(n, f)
            print(f"          {speedkit.load()} at the end of the block", flush=True)
    if args.validation_parts and args.sizes:
        vp = validation_parts(largest, args.repeat, seed)
        print(f"\nfree-run validation, {vp['rows']} rows, {vp['substeps']} RK4 substep(s), steps of {vp['stride']} "
              f"sample(s), CPU s (best of {args.repeat}): validate {vp['validate']:.3f}; alone: input on the half-step "
              f"grid {vp['input_grid']:.3f}, RK4 run {vp['rk4']:.3f} (in steps of one sample {vp['rk4_one_sample']:.3f}), "
              f"the displacement through the band with its 2 derivatives {vp['band_limit']:.3f}, "
              f"7 fit metrics (3 signals held out and all, 1 one-step) {vp['metrics']:.3f}", flush=True)
    if args.uncertainty_parts and args.sizes:
        up = uncertainty_parts(largest, args.repeat, seed)
        print(f"\nuncertainty step, n = {largest}, CPU s (best of {args.repeat}), parts alone: all-rows refits "
              f"and covariances {up['refits']:.3f}, closed-form chain bias {up['closed_form']:.3f} (of which noise "
              f"floors {up['floors']:.3f} (read from the chain's spectra), the noise's share of the variance "
              f"{up['noise_share']:.3f}), inclusion probabilities ({N_PLACEMENTS} placements) {up['inclusion']:.3f} "
              f"(of which ADMM paths {up['paths']:.3f})", flush=True)
    if args.padding_lever and args.sizes:
        lev = padding_lever(largest, args.repeat, seed)
        print(f"\npadding, n = {largest}: chain CPU {lev['chain_cpu']:.3f} s padded to 2n, "
              f"{lev['cut_cpu']:.3f} s padded by {lev['periods']:g} periods of f_lo; states move by (max / peak) "
              + ", ".join(f"{k} {d:.1e}" for k, d in lev["difference"].items()), flush=True)
    if args.no_simulation:
        return 0
    s = simulation_figures(args.repeat)
    print(f"\nfree run, {s['samples']} samples (60 s sweep): solve_ivp RK45 rtol 1e-8: {s['solve_ivp_rk45_s'][0]:.3f} s, "
          f"error {s['solve_ivp_rel_error']:.2e} of peak")
    for r in s["shakeid"]:
        print(f"  shakeid RK4 x{r['substeps']}: {r['seconds'][0]:.4f} s, error {r['rel_error']:.2e}")
    eq = s.get("equal_accuracy")
    if eq:
        print(f"  at equal accuracy ({eq['substeps']} substeps): {eq['speedup']:.0f}x faster (target >= 100x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
