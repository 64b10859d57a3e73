"""Text that can be stored and served: checked at the door, cleaned on the way out.

JSON can carry what is not text: a lone UTF-16 surrogate ("\\ud800" decodes to a str UTF-8 cannot
encode) and control characters. At the door (deps.valid_text) a body holding either is refused with 422
naming the field; on the way out (the catalog's rows, a 422's echo of the input) any such character
already stored is replaced by U+FFFD, so a listing never fails on text stored by an older version.
"""
from __future__ import annotations

import math
import re

#: control characters no field of the service takes (tab, newline and carriage return are text)
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")
_SURROGATE = re.compile(r"[\ud800-\udfff]")


def problem(text: str) -> str | None:
    """Why `text` is not text the service keeps, in words; None when it is."""
    if (m := _SURROGATE.search(text)) is not None:
        return (f"is not valid text: character {m.start() + 1} is a lone UTF-16 surrogate (U+{ord(m.group()):04X}), "
                "which is not a character; send the text as UTF-8")
    if (m := _CONTROL.search(text)) is not None:
        return f"is not valid text: character {m.start() + 1} is the control character U+{ord(m.group()):04X}"
    return None


def first_problem(value, loc: tuple = ()) -> tuple[tuple, str] | None:
    """(where, why) of the first string in a parsed JSON value (keys included) that is not text; None if all are."""
    if isinstance(value, str):
        why = problem(value)
        return (loc, why) if why else None
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(key, str) and (why := problem(key)):
                return (*loc, cleaned(key)), f"the name of this field {why}"
            if found := first_problem(item, (*loc, key)):
                return found
    elif isinstance(value, list):
        for i, item in enumerate(value):
            if found := first_problem(item, (*loc, i)):
                return found
    return None


def cleaned(value):
    """`value` (a str, or JSON-like lists and dicts of them) with every lone surrogate replaced by U+FFFD
    (a valid pair written as two escapes becomes its character): safe to encode as UTF-8."""
    if isinstance(value, str):
        if _SURROGATE.search(value) is None:
            return value
        return value.encode("utf-16", "surrogatepass").decode("utf-16", "replace")
    if isinstance(value, dict):
        return {cleaned(k): cleaned(v) for k, v in value.items()}
    if isinstance(value, list):
        return [cleaned(v) for v in value]
    return value


def finite(obj):
    """JSON has no NaN/inf: non-finite floats as None, in JSON-like lists and dicts (the sender's data,
    never a crash: the controller's link and the catalog's Catalog.set_info)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    return obj
