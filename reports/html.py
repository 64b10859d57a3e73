"""The HTML both report folders are written in: one page with numbered tables and figures, each with a
caption saying what it shows and how to read it. Plain HTML with a little CSS: it opens from the file
system, from the service's /report/ route and from an e-mail attachment alike."""
from __future__ import annotations

import html
import re
import time
from pathlib import Path

from identify.errors import ShakeidError

#: a cell that is a number: "-3.7291", "1.2e+06", "-970.96 ± 0.089", "1 (exact)", "99.90 %"
_NUMBER = re.compile(r"[-+−]?\d[\d.]*(e[-+]?\d+)?( ± \d[\d.]*(e[-+]?\d+)?| \(exact\))?( %)?")

STYLE = ("body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;line-height:1.4}"
         "table{border-collapse:collapse;margin:.5em 0}th,td{border:1px solid #bbb;padding:.2em .6em}"
         "td.num{text-align:right;white-space:nowrap;font-variant-numeric:tabular-nums}th{background:#eee}"
         "caption{caption-side:bottom;text-align:left;font-size:.9em;color:#333;padding-top:.3em}"
         "figure{margin:1.5em 0}figure img{max-width:100%}figcaption{font-size:.9em;color:#333}"
         ".note{font-size:.9em;color:#333}")


#: What each kind of report writes beside its index.html (reports.identification, reports.explain take
#: theirs from here). A folder holds one report: a new report replaces an earlier one of its own kind and
#: refuses a folder that holds the other kind or files shakeid did not write (check_report_folder).
IDENTIFICATION_FIGURES = ("input.png", "output.png", "lambda_path.png", "validation.png")
IDENTIFICATION_DOCUMENTS = ("model.json", "coefficients.md")
EXPLAIN_FIGURES = ("residual_time.png", "residual_state.png", "candidates.png", "gap.png")
#: drawn by both when their document carries a side-by-side frequency response (reports.frf_overlay)
OVERLAY_FIGURES = ("frf_overlay.png",)
EXPLAIN_DOCUMENTS = ("explain.json",)
FRF_FIGURES, FRF_DOCUMENTS = ("frf.png",), ("frf.json",)  # reports.frf (shakeid frf --report)
KINDS = {"identification": (*IDENTIFICATION_FIGURES, *OVERLAY_FIGURES, *IDENTIFICATION_DOCUMENTS),
         "explain": (*EXPLAIN_FIGURES, *OVERLAY_FIGURES, *EXPLAIN_DOCUMENTS), "frf": (*FRF_FIGURES, *FRF_DOCUMENTS)}
#: where a report of each kind goes when the folder holds the other kind (a suggestion in the refusal)
_SUBFOLDER = {"identification": "identify", "explain": "explain", "frf": "frf"}
#: the page's titles before it carried the generator tag (reports written by earlier versions)
_TITLES = {"identification": "<title>Identification report", "explain": "<title>Discrepancy report",
           "frf": "<title>Frequency response"}


def generator(kind: str) -> str:
    """The tag a report page carries to say which kind of shakeid report it is."""
    return f"shakeid {kind} report"


def report_kind(out_dir) -> str | None:
    """Which shakeid report the folder holds ("identification", "explain"), by its index.html; None when
    it has no index.html; "foreign" for an index.html shakeid did not write."""
    page = Path(out_dir) / "index.html"
    if not page.is_file():
        return None
    try:
        head = page.read_bytes()[:4096].decode("utf-8", "replace")
    except OSError:
        return "foreign"
    for kind in KINDS:
        if f"<meta name='generator' content='{generator(kind)}'>" in head or head.startswith(
                "<!doctype html>") and _TITLES[kind] in head:
            return kind
    return "foreign"


def report_folder(out_dir, kind: str) -> Path:
    """The report folder `out_dir` for a report of `kind`, created, with every file an earlier report of
    the same kind wrote there removed (a figure the new one does not write, validation.png of a fit that
    was not validated, must not be left beside its page). check_report_folder refuses first what must not
    be replaced."""
    out = check_report_folder(out_dir, kind)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ShakeidError(f"{out}: cannot create the report folder: {exc.strerror or exc}") from None
    for name in ("index.html", *KINDS[kind]):
        (out / name).unlink(missing_ok=True)
    return out


def check_report_folder(out_dir, kind: str) -> Path:
    """out_dir as a Path, checked before any work (a refused folder wastes no fit): ShakeidError when it
    is a file, when it holds the other kind of report (an explain report would delete the identification
    report's model.json, which may be the very --model it explains), or when it holds an index.html or a
    report's file names that shakeid did not write (the operator's own files are never overwritten)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ShakeidError(f"{out}: is a file, not a folder; a report is a folder of files (give a new or "
                           "existing folder)")
    if not out.is_dir():
        return out
    held = report_kind(out)
    every = dict.fromkeys(("index.html", *(f for files in KINDS.values() for f in files)))  # each name once
    names = [n for n in every if (out / n).exists()]
    if held in KINDS and held != kind:
        theirs = [n for n in names if n == "index.html" or n in KINDS[held]]
        raise ShakeidError(f"{out}: holds {_a(held)} report ({', '.join(theirs)}); {_a(kind)} report there would "
                           f"replace it: give another folder, e.g. {out / _SUBFOLDER[kind]}")
    foreign = [n for n in names if held != kind or n not in ("index.html", *KINDS[kind])]
    if foreign:
        raise ShakeidError(f"{out}: holds {', '.join(foreign)}, not written by a shakeid {kind} report; they are "
                           f"never overwritten: give another folder, e.g. {out / _SUBFOLDER[kind]}")
    return out


def _a(kind: str) -> str:
    return f"an {kind}" if kind[0] in "aeiou" else f"a {kind}"


def earlier_report(out_dir) -> str | None:
    """When `out_dir` holds a report (its index.html), when it was written, as the operator is told before
    a new one replaces it: "the report written there at 2026-11-24 08:41:02"; else None."""
    page = Path(out_dir) / "index.html"
    if not page.is_file():
        return None
    return "the report written there at " + time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(page.stat().st_mtime))


def esc(text) -> str:
    return html.escape(str(text))


def _is_number(cell: str) -> bool:
    return bool(_NUMBER.fullmatch(cell))


class Page:
    """One report page; tables and figures are numbered in the order they are added."""

    def __init__(self, title: str, kind: str):
        self.title, self.kind = title, kind  # kind: "identification" or "explain" (the generator tag)
        self.parts: list[str] = [f"<h1>{esc(title)}</h1>"]
        self.n_tables = self.n_figures = 0

    def heading(self, text: str) -> None:
        self.parts.append(f"<h2>{esc(text)}</h2>")

    def paragraph(self, text: str, cls: str = "") -> None:
        self.parts.append(f"<p{' class=' + repr(cls) if cls else ''}>{esc(text)}</p>")

    def code(self, text: str, caption: str) -> None:
        """Source text to copy (the model's LaTeX), preformatted, its caption before it."""
        self.parts.append(f"<p>{esc(caption)}</p><pre>{esc(text)}</pre>")

    def table(self, headers, rows, caption: str) -> None:
        """A table with a numbered caption under it; the first column names the row, numeric cells in the
        others are right-aligned."""
        self.n_tables += 1
        head = "".join(f"<th>{esc(h)}</th>" for h in headers)
        body = "".join("<tr>" + "".join(f"<td class='num'>{esc(c)}</td>" if i and _is_number(str(c)) else f"<td>{esc(c)}</td>"
                                        for i, c in enumerate(row)) + "</tr>" for row in rows)  # column 0: names
        self.parts.append(f"<table><caption><b>Table {self.n_tables}.</b> {esc(caption)}</caption>"
                          f"<tr>{head}</tr>{body}</table>")

    def figure(self, src: str, caption: str) -> None:
        """A figure (a PNG beside the page) with a numbered caption under it."""
        self.n_figures += 1
        self.parts.append(f"<figure><img src='{esc(src)}' alt='{esc(src)}'><figcaption><b>Figure {self.n_figures}."
                          f"</b> {esc(caption)}</figcaption></figure>")

    def links(self, items) -> None:
        """[(href, text)]: the machine-readable files beside the page."""
        self.parts.append("<p class='note'>Files: " + ", ".join(f"<a href='{esc(h)}'>{esc(t)}</a>" for h, t in items)
                          + "</p>")

    def render(self) -> str:
        return (f"<!doctype html><html lang='en'><meta charset='utf-8'><title>{esc(self.title)}</title>"
                f"<meta name='generator' content='{generator(self.kind)}'>"
                f"<style>{STYLE}</style><body>" + "\n".join(self.parts) + "</body></html>\n")
