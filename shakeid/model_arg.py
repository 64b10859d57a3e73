"""The MODEL.json argument of the commands that take an identified model (frf, plan-campaign, export):
declared once, read and checked once."""
from __future__ import annotations

from identify.errors import ShakeidError

MODEL_HELP = "the model: what `shakeid identify --json` prints, or a report's or the service's model.json"


def add_model_arguments(parser, verb: str) -> None:
    """MODEL.json and --accept-failed; verb: what the command does with it ("use", "export")."""
    parser.add_argument("model", metavar="MODEL.json", help=MODEL_HELP)
    parser.add_argument("--accept-failed", action="store_true",
                        help=f"{verb} a model whose identification failed (its status in MODEL.json)")


def read_model(args, verb: str, check=None):
    """The SparseModel in args.model: refused when its identification failed (unless --accept-failed) or
    when check(model) refuses it; every message starts with the file's name."""
    from identify.model import SparseModel, read_document

    doc = read_document(args.model)
    if doc.get("status") == "failed" and not args.accept_failed:
        raise ShakeidError(f"{args.model}: its identification failed ({doc.get('reason') or 'no reason given'}); "
                           f"it is not a model of the rig (--accept-failed {verb}s it anyway)")
    try:
        model = SparseModel.from_dict(doc)
        if check is not None:
            check(model)
    except ShakeidError as exc:
        raise ShakeidError(f"{args.model}: {exc}") from None
    return model
