"""The dashboard for months of recordings, in a real browser (Debian's Chromium, Playwright) against a real
`shakeid serve`: pages ("1–50 of 65"), filters (date, origin, status, campaign), search, archiving with a
confirmation (the file moved, never deleted), aborted recordings shown as such, the live plot's axes and
idle state, and the security headers (CSP, frame-ancestors, X-Frame-Options) on every response.

The months of recordings are written into the service's own catalog (server.catalog.Catalog on its SQLite
file, as the controller writes sweeps' rows): 65 uploads would take minutes of checking; what is tested is
what the page and the API make of the rows.
"""
from __future__ import annotations

import datetime
import time
from pathlib import Path

import pytest

from identify.data.recording import write_csv
from server.catalog import Catalog, new_id
from protocol.sweep import SineSweep

from .conftest import OPERATOR, Service, wait_for
from .test_dashboard import browser, page, sweep_body, wait_idle  # noqa: F401 - fixtures and helpers shared
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

N_RECORDINGS = 65
DAY_S = 86400.0


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    s = Service(tmp_path_factory.mktemp("dash-list") / "data", speed=10.0).start()
    yield s
    s.stop()


@pytest.fixture(scope="module")
def months(service) -> list[dict]:
    """N_RECORDINGS recordings over about two months (newest first): every 5th aborted (its signals clean),
    uploads and sweeps alternating, one with a note; and a campaign of three of them."""
    cat = Catalog(service.data_dir / "catalog.sqlite")
    now, rows = time.time(), []
    for i in range(N_RECORDINGS):
        rec = {"id": new_id(), "created": now - DAY_S * i - 3600, "origin": "upload" if i % 2 else "sweep",
               "filename": f"run-{i:02d}.csv", "path": str(service.data_dir / f"none-{i}.csv"),
               "status": "aborted" if i % 5 == 0 else "complete", "sweep_id": None,
               "info": {"quality": {"usable_for_identification": True, "flags": 0, "flagged": [], "reasons": []},
                        **({"reason": "operator abort"} if i % 5 == 0 else {}),
                        **({"sweep": {"f_start_hz": 1, "f_end_hz": 20, "duration_s": 60, "amplitude_mm": 1.0,
                                      "note": "resonance check"}} if i == 12 else {})}}
        cat.insert("recordings", **rec)
        rows.append(rec)
    # a campaign row as the controller writes it (GET /api/campaigns validates every field)
    sweeps = [{"index": n + 1, "amplitude_mm": 1.0, "direction": "up", "repeat": 1, "f_start_hz": 1.0, "f_end_hz": 20.0,
               "duration_s": 60.0, "settle_s": 2.0, "status": "complete", "sweep_id": None,
               "recording_id": rows[k]["id"]} for n, k in enumerate((3, 4, 7))]
    cat.insert("campaigns", id="c0ffee000001", created=now, updated=now, name="drift-series", state="completed",
               reason=None, operator="", plan={"name": "drift-series"}, sweeps=sweeps,
               progress={"done": 3, "total": 3}, recording_ids=[rows[k]["id"] for k in (3, 4, 7)])
    cat.close()
    return rows


def shown(page) -> list[str]:
    return page.locator("#recs tr[data-id]").evaluate_all("rows => rows.map(r => r.dataset.id)")


def range_is(page, text: str) -> None:
    page.wait_for_selector(f"#recs-range:text-is('{text}')")


def local_day(t: float) -> str:
    return datetime.date.fromtimestamp(t).isoformat()


def test_pages_filters_and_search(page, service, months):
    ids = [r["id"] for r in months]
    range_is(page, f"1–50 of {N_RECORDINGS}")
    assert shown(page) == ids[:50]  # newest first
    page.click("#recs-next")
    range_is(page, f"51–{N_RECORDINGS} of {N_RECORDINGS}")
    assert shown(page) == ids[50:] and page.locator("#recs-next").is_disabled()
    page.click("#recs-prev")
    range_is(page, f"1–50 of {N_RECORDINGS}")

    page.select_option("#f-status", "aborted")  # aborted shown as such: never "clean", no identify button
    aborted = [r["id"] for r in months if r["status"] == "aborted"]
    range_is(page, f"1–{len(aborted)} of {len(aborted)}")
    assert shown(page) == aborted
    for row in page.locator("#recs tr[data-id]").all():
        assert "unusable: status is aborted" in row.locator("td.quality").inner_text() and "clean" not in row.inner_text()
        assert "not identified (aborted)" in row.locator("td.fit").inner_text()
        assert row.locator("button.identify").count() == 0
    page.select_option("#f-status", "")

    page.select_option("#f-origin", "upload")
    uploads = [r["id"] for r in months if r["origin"] == "upload"]
    range_is(page, f"1–{len(uploads)} of {len(uploads)}")
    assert shown(page) == uploads
    page.select_option("#f-origin", "")

    # dates: the local days of the 10th to the 20th recording, both ends included
    since, until = local_day(months[20]["created"]), local_day(months[10]["created"])
    page.fill("#f-since", since)
    page.fill("#f-until", until)
    page.locator("#f-until").dispatch_event("change")
    in_range = [r["id"] for r in months if since <= local_day(r["created"]) <= until]
    range_is(page, f"1–{len(in_range)} of {len(in_range)}")
    assert shown(page) == in_range and len(in_range) == 11
    page.fill("#f-since", "")
    page.fill("#f-until", "")
    page.locator("#f-until").dispatch_event("change")

    page.select_option("#f-campaign", "c0ffee000001")
    range_is(page, "1–3 of 3")
    assert shown(page) == [months[k]["id"] for k in (3, 4, 7)]
    page.select_option("#f-campaign", "")

    page.fill("#f-q", "run-07")  # the search: file name, id, note, operator
    range_is(page, "1–1 of 1")
    assert shown(page) == [months[7]["id"]]
    page.fill("#f-q", "resonance")
    page.wait_for_selector(f"#recs tr[data-id='{months[12]['id']}']")  # the same "1–1 of 1" as before
    range_is(page, "1–1 of 1")
    assert shown(page) == [months[12]["id"]]
    page.fill("#f-q", "no such recording")
    range_is(page, "0–0 of 0")
    assert "no recordings match" in page.inner_text("#recs")


def test_archive_asks_first_and_moves_the_file(page, service, months, make_run, tmp_path):
    path = tmp_path / "to-archive.csv"
    write_csv(path, make_run(sweep=SineSweep(duration_s=5.0), fs_hz=500.0).recording)
    with service.client() as api:
        rec = api.post("/api/recordings", params={"filename": path.name}, content=path.read_bytes()).json()
    stored = Path(rec["path"]) if "path" in rec else service.data_dir / "recordings" / f"{rec['id']}.csv"
    assert stored.exists()
    row = page.locator(f"#recs tr[data-id='{rec['id']}']")
    row.wait_for()
    page.once("dialog", lambda d: d.dismiss())  # the operator changes their mind: nothing happens
    row.locator("button.archive").click()
    assert stored.exists() and row.count() == 1
    messages = []
    page.once("dialog", lambda d: (messages.append(d.message), d.accept()))
    row.locator("button.archive").click()
    page.wait_for_selector(f".msg:has-text('recording {rec['id']} archived')")
    assert "nothing is deleted" in messages[0]
    archived = service.data_dir / "archive" / stored.name
    assert archived.read_bytes() == path.read_bytes() and not stored.exists()
    row.wait_for(state="detached")
    with service.client() as api:
        assert api.get(f"/api/dashboard/recordings/{rec['id']}").json()["archived"] is not None
    page.check("#f-archived")
    row.locator("button.restore").click()
    page.wait_for_selector(f".msg:has-text('recording {rec['id']} restored')")
    assert stored.read_bytes() == path.read_bytes() and not archived.exists()
    page.uncheck("#f-archived")
    row.wait_for()


def test_live_plot_has_axes_says_idle_and_counts_time_into_the_sweep(page, service):
    blank_margin = ("(() => { const c = document.getElementById('live'), g = c.getContext('2d');"
                    " const d = g.getImageData(0, 0, 66, c.height).data; let n = 0;"
                    " for (let i = 3; i < d.length; i += 4) n += d[i] > 0; return n; })()")
    with service.client() as api:
        wait_idle(api)
        page.wait_for_selector("#live[data-state='idle']")
        assert "no sweep running" in page.inner_text("#live-state")
        assert page.evaluate(blank_margin) > 100  # the acceleration axis' labels, drawn when idle too
        api.post("/api/sweeps", json=sweep_body(60.0))
        page.wait_for_selector("#live[data-state='live']")
        wait_for(lambda: page.evaluate("points.length") > 200, 30, "samples in the plot")
        first, last = page.evaluate("[points[0][0], points[points.length - 1][0]]")
        # time into the sweep: from 0 at the recording's start (the rig's clock had run for minutes)
        # (a viewer joins a moment after the start, later on a loaded machine: its first point is seconds in, never
        # the rig clock's hundreds; the sweep lasts 60 s)
        assert 0 <= first < last < 62
        assert "s into the sweep" in page.inner_text("#live-state")
        api.post("/api/rig/estop")
        wait_idle(api)


def test_every_response_carries_the_security_headers_and_no_page_may_frame_it(page, service):
    with service.client() as api:
        for path in ("/", "/static/dashboard.js", "/api/health", "/api/dashboard/recordings", "/api/nothing-here",
                     "/openapi.json"):
            r = api.get(path)
            csp = r.headers.get("content-security-policy", "")
            assert "frame-ancestors 'none'" in csp and r.headers.get("x-frame-options") == "DENY", path
            assert "script-src 'self'" in csp and r.headers.get("x-content-type-options") == "nosniff", path
    # another site framing the dashboard gets nothing: the browser refuses to render it in the frame
    violations = []
    page.on("console", lambda m: violations.append(m.text) if "Content Security Policy" in m.text else None)
    page.reload()
    page.wait_for_selector("#session:has-text('operator')")
    page.wait_for_selector("#recs tr")
    assert not violations, violations  # the page itself keeps to its policy
    page.goto("about:blank")
    page.set_content(f"<iframe id='f' src='{service.url}/#token={OPERATOR}'></iframe>")
    page.wait_for_function("() => document.getElementById('f').contentWindow !== null")
    frame = page.frames[1]
    frame.wait_for_load_state()
    assert "shakeid" not in frame.content() and frame.url != f"{service.url}/"
