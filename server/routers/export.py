"""A recording's latest model as a file to use elsewhere: FMU, C, Python or LaTeX (identify.export, the
same files `shakeid export` writes; docs/export.md)."""
from __future__ import annotations

import tempfile
from pathlib import Path as FsPath
from typing import Literal

from fastapi import APIRouter, Depends, HTTPException
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from identify.errors import ShakeidError
from identify.export import FORMATS, CompilerError, export_model
from identify.model import SparseModel, read_document

from .. import schemas
from ..deps import ERRORS, Id, Services, services, viewer
from .results import latest_result

#: the URL's suffix -> (export format, media type); one entry per identify.export.FORMATS key
SUFFIXES = {FORMATS[f][0].lstrip("."): (f, m) for f, m in (("fmu", "application/octet-stream"),
                                                              ("c", "text/x-csrc; charset=utf-8"),
                                                              ("python", "text/x-python; charset=utf-8"),
                                                              ("latex", "application/x-tex; charset=utf-8"))}
router = APIRouter(tags=["jobs"], dependencies=[viewer], responses={**ERRORS, 404: {"model": schemas.Problem}})


def _build(model_json: FsPath, fmt: str, rec_id: str) -> bytes:
    """The export's bytes, built in a temporary folder (a service's FMU: a C compiler run, ~0.3 s)."""
    model = SparseModel.from_dict(read_document(model_json))
    with tempfile.TemporaryDirectory(prefix="shakeid-export-") as tmp:
        out = FsPath(tmp) / f"model_{rec_id}{FORMATS[fmt][0]}"
        export_model(model, fmt, out, title=f"shakeid model of recording {rec_id}")
        return out.read_bytes()


@router.get("/api/recordings/{rec_id}/model.{suffix}",
            response_class=Response,
            responses={200: {"content": {m.split(";")[0]: {} for _, m in SUFFIXES.values()},
                             "description": "the file, as an attachment"},
                       503: {"model": schemas.Problem, "description": "no C compiler on the service's machine"}})
async def model_file(suffix: Literal["fmu", "c", "py", "tex"], rec_id: str = Id(),
                     svc: Services = Depends(services)) -> Response:
    """The latest identified model as an FMI 2.0 Co-Simulation FMU (model.fmu), a C file (model.c), a numpy
    module (model.py) or LaTeX equations (model.tex): what `shakeid export` writes of its model.json."""
    fmt, media = SUFFIXES[suffix]
    model_json = latest_result(svc, rec_id, "identify", "model.json")
    try:
        data = await run_in_threadpool(_build, model_json, fmt, rec_id)
    except CompilerError as exc:
        raise HTTPException(503, f"cannot build the FMU here: {exc}") from None
    except ShakeidError as exc:
        raise HTTPException(422, f"recording {rec_id}'s model cannot be exported as {fmt}: {exc}") from None
    return Response(data, media_type=media,
                    headers={"Content-Disposition": f'attachment; filename="model_{rec_id}.{suffix}"'})
