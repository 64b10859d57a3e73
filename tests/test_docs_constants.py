"""Where the docs quote a constant as `NAME` (= value), the value is the code's: a constant changed in the code
and not in the docs fails here (the docs name constants by name, house rule)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
QUOTED = re.compile(r"`([A-Z][A-Z0-9_]+)` \(= ([^)]+)\)")


def _constants() -> dict[str, list]:
    """Module-level NAME = literal assignments in the packages, by name (a name may be in several modules)."""
    found: dict[str, list] = {}
    aliases: list[tuple[str, str]] = []  # NAME = OTHER_NAME (e.g. RUNAWAY_BOUND = RIG_STATE_BOUND)
    for package in ("identify", "protocol", "sim", "daq", "reports", "server", "shakeid"):
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.parse(path.read_text()).body:
                if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
                    if isinstance(node.value, ast.Name):
                        aliases.append((node.targets[0].id, node.value.id))
                        continue
                    try:
                        found.setdefault(node.targets[0].id, []).append(ast.literal_eval(node.value))
                    except ValueError:
                        pass
    for name, other in aliases:
        found.setdefault(name, []).extend(found.get(other, []))
    return found


def test_quoted_constants_match_the_code():
    constants = _constants()
    quotes = [(doc.name, m.group(1), m.group(2)) for doc in [*(ROOT / "docs").glob("*.md"), ROOT / "README.md"]
              for m in QUOTED.finditer(doc.read_text())]
    assert quotes, "no quoted constants found: the pattern no longer matches the docs"
    for doc, name, text in quotes:
        assert name in constants, f"{doc}: `{name}` is not a constant in the code"
        assert any(ast.literal_eval(text) == v for v in constants[name]), f"{doc}: {name} (= {text}), code {constants[name]}"
