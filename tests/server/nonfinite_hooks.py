"""Schemathesis hook (SCHEMATHESIS_HOOKS=nonfinite_hooks): every number in a generated JSON body is sent
as NaN, Infinity, -Infinity or 1e400, literals Python's JSON parser accepts but JSON cannot carry back.
Each body sent is counted in the file $NONFINITE_COUNT_FILE, so the test knows they were sent."""
import json
import os

import schemathesis

LITERALS = ("NaN", "Infinity", "-Infinity", "1e400")


def _poison(obj, counter):
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return obj
    if isinstance(obj, (int, float)):
        counter[0] += 1
        return LITERALS[counter[0] % len(LITERALS)]  # a marker string, unquoted below
    if isinstance(obj, dict):
        return {key: _poison(v, counter) for key, v in obj.items()}
    if isinstance(obj, list):
        return [_poison(v, counter) for v in obj]
    return obj


@schemathesis.hook
def map_body(ctx, body):
    if not isinstance(body, (dict, list)):
        return body
    counter = [0]
    text = json.dumps(_poison(body, counter))
    for lit in LITERALS:
        text = text.replace(f'"{lit}"', lit)
    if counter[0]:
        with open(os.environ["NONFINITE_COUNT_FILE"], "a") as f:
            f.write(text[:200] + "\n")
    return text.encode()  # bytes: sent as they are
