"""Silverbox benchmark: identify on the estimation range, free-run simulate the test ranges.

    python benchmarks/silverbox.py --json

Scoring as in the data set's README: free-run simulation from each test set's input; the first 50 outputs
only set the initial state (here: least-squares fit of (y', y) at the test set's start on those 50
samples); score 1000 * RMSE(y[50:], y_sim[50:]) in mV. Without --json a table with the published figures
is printed. Variants run side by side: the default identification; a budget of 7 terms chosen by
equation error (backward elimination) then refit on the free-run error (identify.simulation.refine); the same
budget chosen by free-run error on the estimation data (identify.selection.budget); the same with the winner refit on
all estimation rows (budget_refit="all"); the default with the free-run refit. Nothing but the estimation
range is used to choose terms or fit coefficients.

Two-record variants (`--second-record`, default the vendored Schroeder80mV.mat; `--no-second-record` to
skip them): the same 7-term free-run budget fitted jointly to the estimation range and the
distribution's second record of the circuit (identify.joint; free-run errors pooled over both). Their
estimation data are not the usual split's: the second record is further data of the same circuit (no
test set sees any of it), with output peaks up to 23 % above the estimation range's. Compare them with
published figures only under that convention.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identify.identifier import SparseIdentifier  # noqa: E402
from identify.data.recording import read_recording  # noqa: E402
from identify.simulation.simulate import fine_grid_input, simulate  # noqa: E402

FS_HZ = 1e7 / 2**14
ESTIMATION = (40650, 105712)
TESTS = {"arrow_full": (100, 40575), "arrow_no_extrapolation": (100, 32100), "multisine": (105712, 127400)}
PUBLISHED_MV = {"best linear approximation": 13.5, "PNLSS (Paduart 2010)": 0.3, "deep SUBNET (Beintema 2021)": 1.4,
                "LSTM (Champneys 2024)": 2.7}
N_INIT = 50
SECOND_RECORD = Path(__file__).resolve().parents[1] / "data/silverbox/Schroeder80mV.mat"
TWO_RECORDS = "two records, budget by free run"


def score(model, u, y, substeps: int) -> dict:
    out = {}
    dt = 1.0 / FS_HZ
    for name, (a, b) in TESTS.items():
        uu, yy = u[a:b], y[a:b]
        u_fine = fine_grid_input(uu[:, None], substeps)
        head = u_fine[: (N_INIT - 1) * 2 * substeps + 1]

        def init_residual(x0, head=head, yy=yy):
            sim = simulate(model, dt, x0, inputs_fine=head, substeps=substeps, n_samples=N_INIT)
            return sim.states[:, 1] - yy[:N_INIT]

        x0 = least_squares(init_residual, [(yy[1] - yy[0]) / dt, yy[0]], x_scale=[1.0, 0.01]).x
        sim = simulate(model, dt, x0, inputs_fine=u_fine, substeps=substeps, n_samples=b - a, bound=1e4)
        err = yy[N_INIT:] - sim.states[N_INIT:, 1]
        out[name] = float(1000 * np.sqrt(np.mean(err**2))) if not sim.diverged else None
    return out


def run(path: str, second: str | None = None) -> dict:
    rec_all = read_recording(path, "force", "V1", "V2", fs_hz=FS_HZ)
    u, y = rec_all.input, rec_all.output
    est = rec_all.slice(*ESTIMATION)
    variants = {
        "default": (SparseIdentifier(), est),
        "max_terms=7 + free-run refit": (SparseIdentifier(max_terms=7, refine="free-run"), est),
        "max_terms=7 budget by free run": (SparseIdentifier(max_terms=7, budget="free-run"), est),
        "same, refit on all est. rows": (SparseIdentifier(max_terms=7, budget="free-run", budget_refit="all"), est),
        "default + free-run refit": (SparseIdentifier(refine="free-run"), est),
    }
    if second:
        both = [est, read_recording(second, "force", "V1", "V2", fs_hz=FS_HZ)]
        variants[TWO_RECORDS] = (SparseIdentifier(max_terms=7, budget="free-run"), both)
        variants["two records, refit on all rows"] = (SparseIdentifier(max_terms=7, budget="free-run",
                                                                       budget_refit="all"), both)
    results = {}
    for label, (ident, data) in variants.items():
        t0, c0 = time.perf_counter(), time.process_time()
        ident.fit(data)
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        substeps = ident.validation_["substeps"]
        results[label] = {"rmse_mv": score(ident.model_, u, y, substeps), "terms": ident.model_.n_terms,
                          "terms_q1_dot": len(ident.model_.equations["q1_dot"]),
                          "model": ident.model_.to_dict()["model"], "seconds": round(elapsed, 2),
                          "cpu_seconds": round(cpu, 2)}
    return results


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", default=str(Path(__file__).resolve().parents[1] / "data/silverbox/SNLS80mV.mat"))
    p.add_argument("--second-record", default=str(SECOND_RECORD),
                   help="the distribution's second record, for the two-record variants (default: vendored)")
    p.add_argument("--no-second-record", action="store_true", help="skip the two-record variants")
    p.add_argument("--json", action="store_true", help="print one JSON object (the budget chosen by free run)")
    args = p.parse_args(argv)
    results = run(args.data, None if args.no_second_record else args.second_record)
    best = results["max_terms=7 budget by free run"]
    if args.json:
        two = results.get(TWO_RECORDS)
        print(json.dumps({"rmse_mv": best["rmse_mv"], "terms": best["terms_q1_dot"], "terms_total": best["terms"],
                          "model": best["model"], "variants": results,
                          "two_records_rmse_mv": two["rmse_mv"] if two else None,
                          "scoring": "1000*RMSE(y[50:], y_sim[50:]); x0 fitted on the first 50 samples"}))
        return 0
    print(f"{'variant':32s} {'terms':>5s} {'arrow_full':>11s} {'arrow_no_ext':>13s} {'multisine':>10s} {'fit s':>6s} "
          f"{'cpu s':>6s}")
    for label, r in results.items():
        m = r["rmse_mv"]
        f = lambda v: "diverged" if v is None else f"{v:.3f}"  # noqa: E731
        print(f"{label:32s} {r['terms_q1_dot']:5d} {f(m['arrow_full']):>11s} {f(m['arrow_no_extrapolation']):>13s} "
              f"{f(m['multisine']):>10s} {r['seconds']:6.1f} {r['cpu_seconds']:6.1f}")
        print(f"{'':32s} q1_dot: {', '.join(r['model']['q1_dot'])}")
    print("published (arrowhead full, mV): " + ", ".join(f"{k} {v}" for k, v in PUBLISHED_MV.items()))
    print("target: arrow_full <= 0.36 mV with <= 7 terms")
    if TWO_RECORDS in results:
        print("two-record variants: estimated on the estimation range and the second record (not the usual split)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
