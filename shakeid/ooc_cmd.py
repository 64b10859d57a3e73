"""`shakeid identify BIG.h5`: the out-of-core path for recordings larger than memory.

Chosen automatically for a DAQ HDF5 recording of more than AUTO_CHUNKED_SAMPLES rows (or with
`--chunked` / `--chunk-samples N`): the file is read chunk by chunk (daq.h5source) and identified by
identify.out_of_core.ChunkedIdentifier with the same options as `shakeid identify`; progress goes to
stderr. With `--scheduler tcp://HOST:PORT` the chunks' normal equations are computed on the Dask
cluster's workers (which must see the file at the same path, as for `shakeid batch`).

The data's quality is the recorder's verdict stored in the file (daq.recorder.read_quality), not
re-assessed (that would be another pass over the record); a recording whose status is not complete
or whose stored verdict is unusable is refused unless --accept-faulty, as in the in-core path.
"""
from __future__ import annotations

import inspect
import sys
from pathlib import Path

from identify.errors import RecordingError, ShakeidError
from identify.data.recording import H5_SUFFIXES

#: Above this many samples an HDF5 recording is identified out of core: 2^24 (2.3 h at 2048 Hz). In core,
#: 1e7 samples peaked at 2.1 GB RSS (2.3 GB with SIMEX; benchmarks/out_of_core.py), so 2^24 needs ~3.5 GB;
#: out of core 0.4 GB at any length.
AUTO_CHUNKED_SAMPLES = 1 << 24


def add_out_of_core_options(q) -> None:
    g = q.add_argument_group("long records (out of core)")
    g.add_argument("--chunked", action="store_true",
                   help=f"read and identify an HDF5 recording chunk by chunk (automatic above {AUTO_CHUNKED_SAMPLES} samples)")
    g.add_argument("--chunk-samples", type=int, metavar="N",
                   help="samples per chunk, the memory bound (default 1048576; implies --chunked)")
    g.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="out of core: compute the chunks on this Dask cluster (the file at the same path on its workers)")


def _file(args) -> str:
    return args.file[0] if isinstance(args.file, (list, tuple)) else args.file


def wants_out_of_core(args) -> bool:
    """--chunked / --chunk-samples / --scheduler, or an HDF5 recording above AUTO_CHUNKED_SAMPLES."""
    if getattr(args, "chunked", False) or getattr(args, "chunk_samples", None) or getattr(args, "scheduler", None):
        return True
    path = _file(args)
    if Path(path).suffix.lower() not in H5_SUFFIXES:
        return False
    from daq.h5source import recording_rows

    samples = getattr(args, "samples", None)
    rows = (samples[1] - samples[0]) if samples else recording_rows(path)
    return rows > AUTO_CHUNKED_SAMPLES


def _progress(stage: str, done: int, total: int, _last={}) -> None:  # noqa: B006  per-process memo
    """'shakeid: scan 40 % (12/30 chunks)' on stderr at every tenth of a stage."""
    step = int(10 * done / max(total, 1))
    if done == 1 or _last.get(stage) != step:  # done == 1: a new stage (or a new run in this process)
        _last[stage] = step
        print(f"shakeid: {stage} {100 * done // max(total, 1)} % ({done}/{total})", file=sys.stderr, flush=True)


def _dask_map(scheduler: str, timeout: float = 10.0):
    """map_chunks on a Dask cluster: every chunk submitted, results as they complete."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ShakeidError("--scheduler needs the dask distributed package") from None
    try:
        client = Client(scheduler, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ShakeidError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None

    def run(fn, jobs):
        futures = [client.submit(fn, *job, pure=False) for job in jobs]
        try:
            for fut in as_completed(futures, loop=client.loop):
                yield fut.result()
        finally:
            client.close()
    return run


def identify_out_of_core(args, ident) -> int:
    """cmd_identify for a long HDF5 recording; `ident` is the SparseIdentifier the options describe."""
    import json

    from daq.h5source import H5ChunkSource
    from daq.recorder import DEFAULT_CHANNELS
    from identify.identifier import SparseIdentifier
    from identify.out_of_core import ChunkedIdentifier

    path = _file(args)
    if Path(path).suffix.lower() not in H5_SUFFIXES:
        raise ShakeidError(f"{path}: out-of-core identification reads the DAQ's HDF5 recordings (not CSV/MAT)")
    if getattr(args, "report", None):
        raise ShakeidError("--report draws the whole record's signals: not available out of core")
    params = {k: getattr(ident, k) for k in inspect.signature(SparseIdentifier.__init__).parameters if k != "self"}
    chunked = ChunkedIdentifier(**params)
    if args.chunk_samples:
        if args.chunk_samples < 4096:
            raise ShakeidError("--chunk-samples must be at least 4096")
        chunked.chunk_samples = args.chunk_samples
    samples = getattr(args, "samples", None)
    src = H5ChunkSource(path, args.input or DEFAULT_CHANNELS[0], args.output or DEFAULT_CHANNELS[1],
                        tuple(samples) if samples else None)
    problems = [] if src.status() == "complete" else [f"status is {src.status()}, not complete"]
    quality = src.quality()
    if quality.get("assessed"):
        problems += quality["reasons"] if not quality["usable_for_identification"] else []
    if problems and not args.accept_faulty:
        raise RecordingError(f"{path}: {'; '.join(problems)} (use --accept-faulty to identify it anyway)")
    print(f"shakeid: {path}: {src.n_samples} samples, out of core in chunks of {chunked.chunk_samples}"
          + (f" on {args.scheduler}" if args.scheduler else ""), file=sys.stderr, flush=True)
    try:
        chunked.fit_source(src, _progress, _dask_map(args.scheduler) if args.scheduler else None)
    except ValueError as exc:  # library/term specification problems
        raise ShakeidError(str(exc)) from None
    finally:
        src.close()
    data = {"data_quality": {"usable_for_identification": not problems, "reasons": problems,
                             "assessed": "by the recorder while recording (stored in the file; not re-assessed "
                                         "out of core)" if quality.get("assessed") else "not assessed",
                             "flags": quality.get("flags", [])}}
    if problems:
        data["accepted_faulty"] = problems
    result = {**chunked.result(), **data}
    if args.json:
        print(json.dumps(result))
    else:
        from reports.text import summary

        print(summary(result, path))
    if result["status"] == "failed":
        print(f"shakeid: identification failed: {path}: {result['reason']}", file=sys.stderr)
        return 1
    return 0
