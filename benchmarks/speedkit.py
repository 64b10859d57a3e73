"""What benchmarks/identify_speed.py needs beside the timing itself: busy processes beside it, the machine's
load and BLAS threads as measured, the CLI timed as a process, and PySINDy at equal quality."""
from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

#: The environment that limits BLAS to one thread (what the CLI's default is compared with).
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: The terms the benchmark's rig has (Table 1), in PySINDy's names: q1 = x0, q2 = x1, zdd = u0.
TRUE_FIRST_EQUATION = {"x0", "x1", "x0 x1^2", "x1^3", "u0"}
#: STLSQ thresholds tried, on unit-RMS columns: pysindy scales each column to unit L2 norm over all rows,
#: so the threshold it is given is this times sqrt(rows). At 1e6 samples 0.030-0.033 keep a spurious
#: q1^2*q2, 0.037-0.041 recover the truth, 0.045 drops the weak q1*q2^2 (one seed, measured).
PYSINDY_THRESHOLDS = (0.030, 0.033, 0.035, 0.037, 0.039, 0.041, 0.043, 0.046)


def load() -> str:
    """The 1-minute load average and the cores, as `uptime` gives them."""
    return f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"


def blas_threads() -> str:
    """The BLAS libraries' thread counts as the process has them (threadpoolctl)."""
    from threadpoolctl import threadpool_info

    return ", ".join(f"{i['internal_api']} {i['num_threads']}" for i in threadpool_info() if i["user_api"] == "blas")


@contextlib.contextmanager
def busy(n: int):
    """n processes spinning `while True: pass` beside the benchmark, stopped (by their pids) after."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        time.sleep(0.5 if n else 0.0)  # they are running before the first timing
        yield procs
    finally:
        for p in procs:
            p.kill()
            p.wait()


def write_mat(path: Path, rec) -> None:
    """The recording as a .mat file shakeid reads (time column t; the channels by their names)."""
    from scipy.io import savemat

    savemat(path, {"t": rec.time_s, rec.input_name: rec.input, rec.output_name: rec.output})


def timed_process(argv, env_extra: dict | None = None) -> dict:
    """Run argv to its end; wall time, user and system CPU seconds (RUSAGE_CHILDREN before and after: one
    child at a time) and its stdout. Exit 1 (a model that fails validation) is a result, not an error."""
    import resource

    env = {**os.environ, **(env_extra or {})}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(map(str, argv))}: exit {done.returncode}: {done.stderr.decode()[-2000:]}")
    return {"wall": wall, "user": after.ru_utime - before.ru_utime, "sys": after.ru_stime - before.ru_stime,
            "stdout": done.stdout}


def cli_figures(path: Path, repeat: int) -> dict:
    """`shakeid identify FILE --json` as a user runs it, default threads and one BLAS thread in alternating
    rounds (best of `repeat` each: wall, user CPU), its parts from the JSON's timings_s (fastest default
    run), and the interpreter's start with `import shakeid.cli` alone (what every command pays first)."""
    shakeid = [str(Path(sys.executable).parent / "shakeid"), "identify", str(path), "--json"]
    runs = {"default": [], "one_thread": [], "import": []}
    for _ in range(repeat):
        runs["default"].append(timed_process(shakeid))
        runs["one_thread"].append(timed_process(shakeid, ONE_THREAD))
        runs["import"].append(timed_process([sys.executable, "-c", "import shakeid.cli"]))
    out = {k: {m: min(r[m] for r in rs) for m in ("wall", "user", "sys")} for k, rs in runs.items()}
    fastest = min(runs["default"], key=lambda r: r["wall"])
    doc = json.loads(fastest["stdout"])
    out["parts"], out["status"], out["model"] = doc["timings_s"], doc["status"], doc["model"]["q1_dot"]
    return out


def pysindy_equal_quality(sig, thresholds=PYSINDY_THRESHOLDS) -> dict:
    """PySINDy given what shakeid's chain made (the band-limited q1, q2, q1_dot and input on the valid
    rows: PySINDy's own trapezoidal integration never recovers the support at 1e6 samples, its drift
    swamps the weak terms), SINDy.fit with the same 16 columns (poly degree 4 in q1, q2, plus zdd),
    STLSQ on normalized columns (threshold per unit-RMS column) and the derivatives given (x_dot = (q1_dot, q1)), at each threshold in
    turn until the first equation's support is the truth's and the second is q1 alone. Its CPU time is
    that one fit's (the search for the threshold, which needs the truth, is not counted)."""
    import pysindy as ps

    v = sig.valid
    q1, q2, qdd, u = (np.asarray(a[v], dtype=float) for a in (sig.q1, sig.q2, sig.q1_dot, sig.input))
    tried, scale = [], np.sqrt(q1.size)
    for thr in thresholds:
        lib = ps.GeneralizedLibrary([ps.PolynomialLibrary(degree=4), ps.IdentityLibrary()],
                                    inputs_per_library=[[0, 1], [2]])
        model = ps.SINDy(optimizer=ps.STLSQ(threshold=thr * scale, normalize_columns=True), feature_library=lib)
        t0, c0 = time.perf_counter(), time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model.fit(np.column_stack([q1, q2]), t=1.0 / sig.fs_hz, x_dot=np.column_stack([qdd, q1]),
                      u=u[:, None])
        t = (time.perf_counter() - t0, time.process_time() - c0)
        names, coef = model.get_feature_names(), model.coefficients()
        first = {names[j] for j in np.flatnonzero(coef[0])}
        second = {names[j] for j in np.flatnonzero(coef[1])}
        tried.append((thr, len(first)))
        if first == TRUE_FIRST_EQUATION and second == {"x0"}:
            return {"threshold": thr, "time": t, "tried": tried,
                    "model": {names[j]: float(coef[0, j]) for j in np.flatnonzero(coef[0])}}
    return {"threshold": None, "time": None, "tried": tried, "model": None}
