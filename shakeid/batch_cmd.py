"""`shakeid batch FILE...`: identify each recording on its own (one model per file) in a local process
pool or on an existing Dask cluster (`--scheduler tcp://HOST:PORT`).

Each file goes through exactly `shakeid identify`'s code path (open_recording, the same refusal of data
that cannot carry a model, SparseIdentifier(...).fit(...).result()) with the same options, so a batch
model is the model `shakeid identify FILE --json` prints, plus "computed_on": the Dask worker's address,
or "local:PID" for the local pool.

Refusals follow `shakeid identify`: a file that cannot be read or cannot carry a model is named with the
problem on stderr and the others are still identified; the JSON lists it under "failed" with the reason.
Exit status: 2 if any file was refused (or an option is wrong: then nothing runs), else 1 if any fitted
model failed its validation or its computation was lost (a worker died), else 0.

On a Dask cluster the workers read the files themselves: every FILE must be readable at the same absolute
path on every worker (a shared volume), and the workers need shakeid installed (same version).
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import sys
from pathlib import Path

from daq.formats import NAMES as FORMAT_NAMES
from identify.errors import ShakeidError

from .argtypes import int_in, positive
from .files import read_recording

EXIT_OK, EXIT_MODEL_FAILED, EXIT_REFUSED = 0, 1, 2


def worker_name() -> str:
    """Where this code runs: the Dask worker's address (tcp://HOST:PORT), else "local:PID"."""
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):  # ValueError: not inside a Dask worker
        return f"local:{os.getpid()}"


def identify_file(args: argparse.Namespace, path: str) -> dict:
    """Identify one recording as `shakeid identify` does; runs in a pool or Dask worker process.

    Returns {"result": identify JSON + computed_on} or {"refused": message, "computed_on": ...}: the
    operator's errors come back as data (never as an exception to unpickle on the other side)."""
    from identify.data.quality import check_identifiable

    where = worker_name()
    one = copy.copy(args)
    one.file = path
    try:
        ident = args.make_identifier(one)
        rec = read_recording(one)
        data = check_identifiable(rec, path, args.accept_faulty)
        try:
            ident.fit(rec)
        except ValueError as exc:  # library/term specification problems, as in `shakeid identify`
            raise ShakeidError(str(exc)) from None
    except ShakeidError as exc:
        message = str(exc)
        if path not in message:
            message = f"{path}: {message}"
        return {"refused": message, "computed_on": where}
    return {"result": {**ident.result(), **data, "computed_on": where}}


def _names(files: list[str]) -> dict[str, str]:
    """{name: absolute path}; the name (the file's name) keys the JSON and the --out files."""
    names: dict[str, str] = {}
    for f in files:
        name = Path(f).name
        if name in names:
            raise ShakeidError(f"two files named {name!r} ({names[name]} and {Path(f).resolve()}): "
                               "the models are keyed by file name; rename one")
        names[name] = str(Path(f).resolve())  # workers elsewhere see the same absolute path, not our cwd
    return names


def _run_local(args, names: dict[str, str], workers: int):
    """Yield (name, outcome) as files finish, in a local process pool."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    n = max(1, min(workers, len(names)))
    with ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(identify_file, args, path): name for name, path in names.items()}
        for fut in as_completed(futures):
            yield futures[fut], _outcome(fut)


def _run_dask(args, names: dict[str, str], scheduler: str):
    """Yield (name, outcome) as files finish, on the Dask cluster at `scheduler`."""
    from distributed import Client, as_completed

    try:
        client = Client(scheduler, timeout=args.connect_timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ShakeidError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    try:
        futures = {client.submit(identify_file, args, path, key=f"shakeid-batch-{name}-{os.getpid()}", pure=False):
                   name for name, path in names.items()}
        for fut in as_completed(list(futures), loop=client.loop):
            yield futures[fut], _outcome(fut)
    finally:
        client.close()


def _outcome(fut) -> dict:
    """A finished future's outcome; a lost computation (a worker died, the cluster went away) is named."""
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - whatever the pool or cluster raised, the file is reported
        return {"lost": f"computation lost: {type(exc).__name__}: {exc}"}


def _line(name: str, result: dict) -> str:
    """One line per model: its terms, its held-out fit, where it was computed."""
    terms = "; ".join(f"{eq}: {' '.join(sorted(t)) or '-'}" for eq, t in result["model"].items())
    fit = ((result.get("validation") or {}).get("heldout") or {}).get("q1_dot", {}).get("fit_percent")
    fit_text = "" if fit is None else f", held-out fit {fit:.2f} %"
    return f"{name}: {result['status']}{fit_text}, {terms} (computed on {result['computed_on']})"


def cmd_batch(args) -> int:
    args.make_identifier(args)  # option errors first, before any file is read or any worker starts
    if args.workers is not None and args.workers < 1:
        raise ShakeidError("--workers must be at least 1")
    names = _names(args.files)
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    if args.scheduler:
        runs = _run_dask(args, names, args.scheduler)
    else:
        runs = _run_local(args, names, args.workers or os.cpu_count() or 1)
    models: dict[str, dict] = {}
    failed: dict[str, dict] = {}
    status = EXIT_OK
    for name, outcome in runs:
        if "result" in outcome:
            result = models[name] = outcome["result"]
            if out:
                # the whole file name: sweep.csv and sweep.h5 are two recordings, two models
                (out / f"{name}.model.json").write_text(json.dumps(result, indent=2))
            if result["status"] == "failed":
                failed[name] = {"reason": f"identification failed: {result['reason']}",
                                "computed_on": result["computed_on"]}
                status = max(status, EXIT_MODEL_FAILED)
                print(f"shakeid: identification failed: {names[name]}: {result['reason']}", file=sys.stderr)
            if not args.json:
                print(_line(name, result))
        else:
            reason = outcome.get("refused") or f"{names[name]}: {outcome['lost']}"
            failed[name] = {"reason": reason, "computed_on": outcome.get("computed_on")}
            status = max(status, EXIT_REFUSED if "refused" in outcome else EXIT_MODEL_FAILED)
            print(f"shakeid: error: {reason}", file=sys.stderr)
    doc = {"models": {k: models[k] for k in names if k in models},
           "failed": {k: failed[k] for k in names if k in failed},
           "scheduler": args.scheduler or "local"}
    kept = 0
    if out:
        index, kept = _merged_index(out / "batch.json", doc)
        (out / "batch.json").write_text(json.dumps(index, indent=2))
    if args.json:
        print(json.dumps(doc))
    else:
        print(f"{len(models) - sum(m['status'] == 'failed' for m in models.values())} of {len(names)} "
              f"file(s) identified on {doc['scheduler']}" + (f"; models in {out}" if out else "")
              + (f" (batch.json also lists {kept} file(s) of earlier batches there)" if kept else ""))
    return status


def _merged_index(path: Path, doc: dict) -> tuple[dict, int]:
    """batch.json for a folder that earlier batches may have written into: each file's latest outcome,
    this run's replacing an earlier one of the same name, the others kept (their models are still in the
    folder). Returns the index and how many files it kept from earlier batches."""
    try:
        old = json.loads(path.read_text())
        earlier = {k: dict(old[k]) for k in ("models", "failed")}
    except (OSError, ValueError, KeyError, TypeError):  # none yet (or not one of ours): this run alone
        return doc, 0
    now = set(doc["models"]) | set(doc["failed"])
    for k in earlier:
        earlier[k] = {name: v for name, v in earlier[k].items() if name not in now}
    index = {"models": {**earlier["models"], **doc["models"]}, "failed": {**earlier["failed"], **doc["failed"]},
             "scheduler": doc["scheduler"]}
    return index, len(earlier["models"]) + len(earlier["failed"])


def add_batch_parser(sub, add_identify_options, make_identifier) -> None:
    """The `batch` subcommand. The CLI hands over how it adds identify's options and builds the identifier
    from them (shakeid/cli.py's), so this module never imports the CLI (no import circle); the function
    travels to the workers with the parsed arguments. Recordings are read as `shakeid identify` reads them
    (shakeid.files.read_recording)."""
    q = sub.add_parser("batch", help="identify each of many recordings on its own, in a local process pool or "
                                     "on a Dask cluster (--scheduler)")
    q.add_argument("files", nargs="+", metavar="FILE", help=f"recordings ({FORMAT_NAMES})")
    q.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="an existing Dask scheduler; the files must be at the same paths on its workers "
                        "(default: a local process pool)")
    q.add_argument("--workers", type=int_in(1), help="local pool: processes (default: the number of CPUs)")
    q.add_argument("--connect-timeout", type=positive, default=10.0, metavar="S",
                   help="--scheduler: seconds to wait for the scheduler, s")
    q.add_argument("--out", metavar="DIR", help="write NAME.model.json per file (NAME: the file's name with its "
                                                "extension, e.g. sweep.h5.model.json) and batch.json here "
                                                "(default: none)")
    q.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    q.add_argument("--accept-faulty", action="store_true",
                   help="identify recordings that are not complete or whose quality flags make them unusable")
    add_identify_options(q)
    q.set_defaults(func=cmd_batch, make_identifier=make_identifier)
