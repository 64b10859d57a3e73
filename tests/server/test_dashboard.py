"""The dashboard in a real browser: Debian's Chromium driven by Playwright, against a real `shakeid serve`
with its simulated rig at 10x (the operator's flows of issue 14).

What the page shows is compared with what the API says (the truth the page must render): sweep progress,
fits, model coefficients, standard errors, inclusion probabilities, physical parameters, campaign state.
Chromium comes from Debian (`make tools` installs it as root); Playwright's own browser download is
never used. A missing browser fails these tests, saying how to install it.
"""
from __future__ import annotations

import re
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

import pytest

from identify.data.recording import write_csv
from protocol.sweep import SineSweep

from .conftest import OPERATOR, VIEWER, Service, jobs_seen, wait_for, wait_while_moving
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


def js_fixed(x: float, digits: int = 0) -> str:
    """JavaScript's `x.toFixed(digits)`, as the dashboard prints numbers: the exact double rounded half up.
    Python's `:.0f` rounds a tie to even, so a progress of 0.085 reads "9 %" on the page and "8" in Python."""
    return str(Decimal(x).quantize(Decimal(1).scaleb(-digits), rounding=ROUND_HALF_UP))


CHROMIUM = "/usr/bin/chromium"
#: as root Chromium needs --no-sandbox; the rest keep it off the (closed) network: no update, sync, QUIC
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
TIMEOUT_MS = 60_000  # for the page's waits: sweeps and identifications on a loaded 2-core machine


@pytest.fixture(scope="module")
def browser():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.fail("the browser tests need the playwright package: pip install -e '.[test]'", pytrace=False)
    if not Path(CHROMIUM).exists():
        pytest.fail(f"the browser tests need Debian's Chromium at {CHROMIUM}: run `make tools` as root, or "
                    "`apt-get install --no-install-recommends chromium` (never `playwright install`)", pytrace=False)
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    s = Service(tmp_path_factory.mktemp("dash") / "data", speed=10.0).start()
    yield s
    s.stop()


@pytest.fixture
def page(browser, service):
    """A fresh browser context signed in by link; collects every request's address and page errors."""
    ctx = browser.new_context(viewport={"width": 1280, "height": 900}, accept_downloads=True)
    pg = ctx.new_page()
    pg.set_default_timeout(TIMEOUT_MS)
    pg.requests, pg.errors = [], []
    pg.on("request", lambda r: pg.requests.append(r.url))
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.goto(f"{service.url}/#token={OPERATOR}")
    pg.wait_for_selector("#session:has-text('operator')")
    yield pg
    assert not pg.errors, f"JavaScript errors in the page: {pg.errors}"
    assert not [u for u in pg.requests if "/null" in u or "/undefined" in u], "a request for a null id"
    ctx.close()


def sweep_body(duration_s: float, amplitude_mm: float = 1.3) -> dict:
    return {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": duration_s, "amplitude_mm": amplitude_mm}


def wait_idle(api):
    """No sweep running and the PLC out of any emergency stop (a failed test must not fail the next ones)."""
    wait_for(lambda: api.get("/api/rig").json()["active_sweep"] is None, what="the rig to be idle")
    if api.get("/api/rig").json()["plc"]["state"] in ("estop", "fault"):
        assert api.post("/api/rig/reset").status_code == 200


def identified(api, rec_id: str) -> dict:
    """The recording once its identification has completed (auto-identify after a complete sweep)."""
    def done():
        rec = api.get(f"/api/recordings/{rec_id}").json()
        return rec if "identify" in rec["info"] else None
    return wait_while_moving(done, lambda: jobs_seen(api), what="the identification")


@pytest.fixture(scope="module")
def sweep_recording(service):
    """A complete 30 s sweep (3 s of wall time at 10x) with its identification, started through the API."""
    with service.client() as api:
        wait_idle(api)
        sweep_id = api.post("/api/sweeps", json=sweep_body(30.0)).json()["id"]
        sweep = wait_for(lambda: (s := api.get(f"/api/sweeps/{sweep_id}").json())["state"] == "completed" and s,
                         what="the sweep")
        return identified(api, sweep["recording_id"])


def fill_sweep(page, duration_s: float, amplitude_mm: float = 1.3):
    page.fill("#f0", "1"), page.fill("#f1", "20"), page.fill("#dur", str(duration_s))
    page.fill("#amp", str(amplitude_mm))


def test_sign_in_by_link_never_shows_the_token(page, service):
    assert OPERATOR not in page.url and "token" not in page.url
    assert OPERATOR not in page.content(), "the token is in the page"
    assert page.locator("#login").is_hidden() and page.locator("#home").is_visible()
    page.reload()  # kept in the browser: still signed in, still not shown
    page.wait_for_selector("#session:has-text('operator')")
    assert OPERATOR not in page.content()
    # the page's own requests carry it in a header; no address but the live stream's may carry it
    assert not [u for u in page.requests if OPERATOR in u and "/live" not in u]

    page.goto(f"{service.url}/#token=not-a-valid-token")
    page.wait_for_selector(".msg.error:has-text('token was refused')")
    assert page.locator("#login").is_visible() and page.locator("#home").is_hidden()
    page.fill("#token", VIEWER)
    page.click("#login button")
    page.wait_for_selector("#session:has-text('viewer')")
    assert VIEWER not in page.content() and page.input_value("#token") == ""
    # a viewer may not act (the API would answer 403): no sweep, campaign, upload, stop or reset controls
    page.wait_for_selector("#read-only")
    for control in ("#start", "#c-start", "#up-send", "#estop", "#reset"):
        assert page.locator(control).is_hidden(), control
    assert page.locator("button.identify").count() == 0
    page.click(".msg.error .dismiss")  # leave no message behind for the next check


def test_sweep_live_plot_moves_then_fit_shown(page, service):
    with service.client() as api:
        wait_idle(api)
        fill_sweep(page, 60.0)  # 6 s of wall time
        page.click("#start")
        page.wait_for_selector(".msg:has-text('started')")
        canvas = page.locator("#live")
        wait_for(lambda: int(canvas.get_attribute("data-points")) > 50, 30, "live samples in the plot")
        image1 = page.evaluate("document.getElementById('live').toDataURL()")
        t1 = page.evaluate("points[points.length - 1][0]")
        page.wait_for_timeout(1000)
        image2 = page.evaluate("document.getElementById('live').toDataURL()")
        t2 = page.evaluate("points[points.length - 1][0]")
        assert t2 > t1 and image2 != image1, "the live plot did not move"
        sweep_id = re.search(r"sweep ([0-9a-f]{12}) started", page.inner_text("#messages")).group(1)
        page.wait_for_selector(f"#sweep-status:has-text('sweep {sweep_id}: completed')")
        rec = identified(api, api.get(f"/api/sweeps/{sweep_id}").json()["recording_id"])
        fit = rec["info"]["identify"]["fit_percent"]
        row = page.locator(f"#recs tr[data-id='{rec['id']}']")
        row.locator(f"td.fit:has-text('{js_fixed(fit, 1)} %')").wait_for()
        assert "1–20 Hz · 60 s · 1.3 mm" in row.inner_text() and "complete" in row.inner_text()


def test_refusal_stays_until_dismissed(page, service):
    with service.client() as api:
        wait_idle(api)
        running = api.post("/api/sweeps", json=sweep_body(300.0, 1.0)).json()["id"]  # 1.3 mm would hit the stops
        page.wait_for_selector(f"#sweep-status:has-text('{running}')")  # the page follows a sweep started elsewhere
        fill_sweep(page, 30.0)
        page.click("#start")
        msg = page.locator(".msg.error", has_text="another sweep is running")
        msg.wait_for()
        page.wait_for_timeout(2500)  # two refreshes later it is still there
        assert msg.count() == 1 and msg.is_visible()
        msg.locator(".dismiss").click()
        assert msg.count() == 0
        page.click("#abort")  # the operator aborts the sweep the page follows
        page.wait_for_selector(f"#sweep-status:has-text('sweep {running}: aborted')")
        assert api.get(f"/api/sweeps/{running}").json()["state"] == "aborted"


def test_estop_shows_real_progress_and_reset_clears_it(page, service):
    with service.client() as api:
        wait_idle(api)
        fill_sweep(page, 300.0, 1.0)  # 1.3 mm over 300 s: the preflight predicts the mass in the end stops
        page.click("#start")
        status = page.locator("#sweep-status")
        wait_for(lambda: (m := re.search(r"· (\d+) %", status.inner_text())) and int(m.group(1)) >= 8, 60,
                 "the sweep to run")
        page.click("#estop")
        page.wait_for_selector(".msg.error:has-text('EMERGENCY STOP sent')")
        page.wait_for_selector("#sweep-status:has-text('aborted at')")
        sweep_id = re.search(r"sweep ([0-9a-f]{12})", status.inner_text()).group(1)
        truth = api.get(f"/api/sweeps/{sweep_id}").json()
        assert truth["state"] == "aborted" and truth["progress"] >= 0.05
        assert "emergency stop" in truth["error"]
        assert f"aborted at {js_fixed(100 * truth['progress'])} % ({truth['error']})" in status.inner_text()
        page.wait_for_selector("#rig:has-text('PLC estop')")
        page.click("#start")  # refused while in emergency stop
        page.wait_for_selector(".msg.error:has-text('emergency stop')")
        page.click("#reset")
        page.wait_for_selector("#rig:has-text('PLC idle')")
        page.wait_for_timeout(2000)
        assert "estop" not in page.inner_text("#rig"), "a stale emergency stop after reset"
        row = page.locator(f"#recs tr[data-id='{truth['recording_id']}']")
        row.wait_for()
        assert f"aborted at {js_fixed(100 * truth['progress'])} %" in row.inner_text() and "emergency stop" in row.inner_text()


def test_upload_then_identify(page, service, make_run, tmp_path):
    run = make_run(sweep=SineSweep(duration_s=30.0), fs_hz=1000.0)
    path = tmp_path / "bench-sweep.csv"
    write_csv(path, run.recording)
    page.set_input_files("#up-file", str(path))
    page.click("#up-send")
    rec_id = re.search(r"as recording ([0-9a-f]{12})", page.locator(".msg", has_text="uploaded").inner_text()).group(1)
    row = page.locator(f"#recs tr[data-id='{rec_id}']")
    row.locator("td.fit:has-text('not yet')").wait_for()
    assert "upload" in row.inner_text() and "bench-sweep.csv" in row.inner_text()
    row.locator("button.identify").click()
    with service.client() as api:
        rec = identified(api, rec_id)
    row.locator(f"td.fit:has-text('{js_fixed(rec['info']['identify']['fit_percent'], 1)} %')").wait_for()


def test_recording_page(page, service, sweep_recording):
    rec_id = sweep_recording["id"]
    with service.client() as api:
        model = api.get(f"/api/recordings/{rec_id}/model").json()
        # the frequency-response overlay is shown in its own section (tests/server/test_frf_dashboard.py)
        plots = [p for p in api.get(f"/api/recordings/{rec_id}/plots").json() if p != "frf_overlay.png"]
        stored = api.get(f"/api/recordings/{rec_id}/file").content
    page.click(f"#recs a[href='#/recording/{rec_id}']")
    page.wait_for_selector("#rec-terms")
    assert "clean" in page.inner_text("#rec-quality") and "1–20 Hz · 30 s · 1.3 mm" in page.inner_text("#rec-body")
    # every term of the model with its coefficient, standard error and inclusion probability as stored
    rows = page.locator("#rec-terms tr").all_inner_texts()[1:]
    shown = {tuple(r.split("\t")[:2]): r.split("\t")[2:] for r in rows}
    assert set(shown) == {(eq, t) for eq, terms in model["model"].items() for t in terms}
    for (eq, term), (coef, se, incl) in shown.items():
        assert float(coef) == pytest.approx(model["model"][eq][term], rel=1e-3)
        if eq in model["uncertainty"]["exact"]:  # q2_dot = q1, by construction
            assert se == "exact" and model["standard_errors"][eq][term] == 0
        else:
            assert float(se) == pytest.approx(model["standard_errors"][eq][term], rel=0.05)
        assert float(incl) == pytest.approx(model["inclusion_probability"][eq][term], abs=0.005)
    k = page.locator("#rec-physical tr:has-text('stiffness k')").first.inner_text().split("\t")
    assert float(k[1]) == pytest.approx(model["physical"]["stiffness_n_per_m"]["value"], rel=1e-3)
    # the report's figures, each loaded as an image
    page.wait_for_function(f"() => [...document.querySelectorAll('#rec-model-figures img')].filter(i => i.naturalWidth > 0)"
                           f".length === {len(plots)}")
    assert len(plots) >= 3
    # b in mm, as the CLI and the report print it
    b = page.locator("#rec-physical tr:has-text('pre-stress b')").inner_text().split("\t")
    assert b[3] == "mm" and float(b[1]) == pytest.approx(1e3 * model["physical"]["prestress_b_m"]["value"], rel=1e-3)
    # the lambda path at the page's width: its text shown at 3/4 of its size or more
    assert page.evaluate("(i => i.clientWidth / i.naturalWidth)(document.querySelector("
                         "'#rec-model-figures img[alt=\"lambda_path.png\"]'))") >= 0.75
    # the whole report from the page: titled with the file's name (no server path), its figures inlined, its
    # own style applied (the dashboard's policy allows that one inline style by its hash)
    with page.expect_popup() as popup:
        page.click("#rec-report")
    report = popup.value
    report.wait_for_url("blob:**")
    # polled from here: the page's policy (no eval) refuses wait_for_function's predicate
    wait_for(lambda: report.evaluate("document.images.length >= 3 && [...document.images].every(i => i.naturalWidth > 0)"),
             30, "the report's figures")
    assert report.title() == f"Identification report: {sweep_recording['filename']}"
    assert report.evaluate("getComputedStyle(document.body).maxWidth") == "1100px"
    report.close()
    with page.expect_download() as download:
        page.click("#rec-download")
    assert Path(download.value.path()).read_bytes() == stored
    # the explanation, queued from the page
    page.click("#rec-explain button[data-job='explain']")
    page.wait_for_selector("#rec-effect", timeout=120_000)
    with service.client() as api:
        explanation = api.get(f"/api/recordings/{rec_id}/explanation").json()
    effect = (explanation["effect"] or "no effect found").replace("_", " ")
    assert effect in page.inner_text("#rec-effect")
    page.wait_for_function("() => [...document.querySelectorAll('#rec-explain-figures img')].some(i => i.naturalWidth > 0)")
    page.click("text=← all recordings")
    page.wait_for_selector("#home:not([hidden])")


def test_rig_history_matches_the_models(page, service, sweep_recording):
    with service.client() as api:
        history = api.get("/api/dashboard/history").json()["points"]
        recs = [p["recording_id"] for p in history if not p["accepted_faulty"]]  # the others: shown on request
        models = {r: api.get(f"/api/recordings/{r}/model").json()["physical"] for r in recs}
    assert sweep_recording["id"] in recs
    page.wait_for_selector("#history svg[data-parameter]")
    # b is shown in mm, as the CLI and the report print it (its points' data-value stay in the model's SI)
    with service.client() as api:
        assert api.get("/api/dashboard/history").json()["parameters"]["prestress_b_m"] == \
            {"symbol": "b", "unit": "mm", "scale": 1000.0}
    assert page.locator("#history svg[data-parameter='prestress_b_m'] text").first.text_content() == "b, mm"
    b_ticks = page.locator("#history svg[data-parameter='prestress_b_m'] text[text-anchor='end']").all_text_contents()
    b_mm = [1e3 * models[r]["prestress_b_m"]["value"] for r in recs]
    assert min(b_mm) - 1 < float(b_ticks[1]) < max(b_mm) + 1, (b_ticks, b_mm)  # the middle tick, in mm
    for key in ("damping_ns_per_m", "stiffness_n_per_m", "cubic_stiffness_n_per_m3", "prestress_b_m"):
        marks = page.locator(f"#history svg[data-parameter='{key}'] g.point")
        assert marks.count() >= len(recs)  # a recording identified since the API call may have joined
        for i in range(marks.count()):
            rec = marks.nth(i).get_attribute("data-rec")
            if rec not in models:
                continue
            assert float(marks.nth(i).get_attribute("data-value")) == pytest.approx(models[rec][key]["value"], rel=1e-9)
            assert float(marks.nth(i).get_attribute("data-se")) == pytest.approx(models[rec][key]["std_error"], rel=1e-9)
            # the error bar spans value +- 2 SE around the point: symmetric about it
            y = [float(v) for v in marks.nth(i).evaluate(
                "g => [g.querySelector('circle').getAttribute('cy'), g.querySelector('line').getAttribute('y1'),"
                " g.querySelector('line').getAttribute('y2')]")]
            assert y[1] - y[0] == pytest.approx(y[0] - y[2], abs=1e-6) and y[1] >= y[0] >= y[2]


def test_campaign_from_the_builder(page, service):
    with service.client() as api:
        wait_idle(api)
        page.fill("#c-name", "dash-amplitudes")
        page.fill("#c-amps", "0.8, 1.3")
        page.fill("#c-f0", "1"), page.fill("#c-f1", "20"), page.fill("#c-dur", "20"), page.fill("#c-settle", "0.5")
        page.check("#c-up"), page.uncheck("#c-down")
        assert "2 sweep(s)" in page.inner_text("#c-plan")
        page.click("#c-start")
        cid = re.search(r"campaign ([0-9a-f]{12}) started", page.locator(".msg", has_text="started").inner_text()).group(1)
        row = page.locator(f"#campaigns tr[data-id='{cid}']")
        row.locator("td.state:has-text('completed')").wait_for(timeout=120_000)
        truth = api.get(f"/api/campaigns/{cid}").json()
    assert truth["state"] == "completed" and [s["amplitude_mm"] for s in truth["sweeps"]] == [0.8, 1.3]
    assert row.locator("td.progress").inner_text().splitlines()[0] == "2/2"
    for rec_id in truth["recording_ids"]:  # each sweep links to its recording, listed with its amplitude
        assert row.locator(f"a[href='#/recording/{rec_id}']").count() == 1
        page.locator(f"#recs tr[data-id='{rec_id}']").wait_for()
    # the joint identification of the campaign's recordings shows with the state the API gives it
    with service.client() as api:
        joint = api.get(f"/api/campaigns/{cid}").json()["joint_identification"]
        listed = {c["id"]: c for c in api.get("/api/campaigns").json()}[cid]["joint_identification"]
    assert joint is not None and listed["id"] == joint["id"]
    row.locator("span.joint").wait_for()
    assert row.locator("span.joint").inner_text().startswith("joint model: ")



def test_failed_fit_is_not_not_yet_and_can_be_forced(page, service):
    """An aborted recording: shown as such (unusable, 'not identified (aborted)', no identify button; never
    'clean' or 'not yet'), identified anyway from its page, which says so, and kept out of the rig history
    unless asked for."""
    with service.client() as api:
        wait_idle(api)
        # aborted while recording the settle (30 s of rest after the sweep): the whole sweep is in the file,
        # so the forced fit is a good one (a sweep cut mid-way may have too little to identify: that fails
        # again, rightly)
        sweep_id = api.post("/api/sweeps", json={**sweep_body(30.0), "settle_s": 30.0}).json()["id"]
        wait_for(lambda: api.get(f"/api/sweeps/{sweep_id}").json()["progress"] >= 1.0, 60, "the sweep's end")
        assert api.post(f"/api/sweeps/{sweep_id}/abort").status_code == 202
        rec_id = wait_for(lambda: (s := api.get(f"/api/sweeps/{sweep_id}").json())["state"] == "aborted"
                          and s["recording_id"], what="the abort")
        row = page.locator(f"#recs tr[data-id='{rec_id}']")
        row.locator("td.fit:has-text('not identified (aborted)')").wait_for()
        assert row.locator("button.identify").count() == 0
        assert "unusable: " in row.locator("td.quality").inner_text() and "clean" not in row.inner_text()
        page.click(f"#recs a[href='#/recording/{rec_id}']")
        page.wait_for_selector("#rec-model p.bad:has-text('not identified: the recording is aborted')")
        assert "unusable" in page.inner_text("#rec-quality")
        page.click("#rec-model button[data-faulty]")
        page.wait_for_selector("#rec-model p.muted:has-text('queued'), #rec-model p.muted:has-text('running')")
        page.wait_for_selector("#rec-faulty, #rec-model p.bad")  # identified, or failed again
        assert page.locator("#rec-faulty").count() == 1, page.inner_text("#rec-model")
        model = api.get(f"/api/recordings/{rec_id}/model").json()
        assert model["accepted_faulty"] and model["accepted_faulty"][0] in page.inner_text("#rec-faulty")
    page.click("text=← all recordings")
    page.wait_for_selector("#history-faulty")
    assert page.locator(f"#history g.point[data-rec='{rec_id}']").count() == 0
    page.check("#history-faulty")
    assert page.locator(f"#history g.point[data-rec='{rec_id}'] circle.faulty").count() == 4  # c, k, k3, b


def test_uncertain_terms_are_said_under_the_model(page, service, make_run, tmp_path):
    """A 3.9 s cut of a sweep (tests/shakeid/test_cli_human.py's case) keeps terms most held-out placements
    leave out: the recording page lists each one left out of the model with its coefficient, standard error
    and P(kept) as model.json stores them, and not in the model's table."""
    run = make_run(sweep=SineSweep(1, 20, 30, 1.3), noise=0.005, seed=0)
    path = tmp_path / "short-cut.csv"
    write_csv(path, run.recording.slice(20000, 28000))
    with service.client() as api:
        rec_id = api.post("/api/recordings", params={"filename": path.name}, content=path.read_bytes()).json()["id"]
        assert api.post(f"/api/recordings/{rec_id}/identify", json={}).status_code == 202
        identified(api, rec_id)
        model = api.get(f"/api/recordings/{rec_id}/model").json()
    uncertain = [(eq, term, u) for eq, terms in model["uncertain_terms"].items() for term, u in terms.items()]
    assert uncertain, model["uncertain_terms"]  # the case has them (q2^2 and q2^4 of q1_dot)
    page.goto(f"{service.url}/#/recording/{rec_id}")
    page.wait_for_selector("#rec-uncertain")
    said = page.inner_text("#rec-uncertain")
    z = model["uncertainty"]["term_rules"]["significant_z"]  # the bound, as the model states it
    assert said.startswith(f"uncertain terms, left out of the model (within {z:g} standard errors of zero)")  # JS String(x)
    for eq, term, u in uncertain:
        assert f"{term} ({eq}) " in said and f"P(kept) {js_fixed(u['inclusion_probability'], 2)}" in said
    shown = {tuple(r.split("\t")[:2]) for r in page.locator("#rec-terms tr").all_inner_texts()[1:]}
    assert shown == {(eq, t) for eq, terms in model["model"].items() for t in terms}  # the model's, read back
    assert not shown & {(eq, term) for eq, term, _ in uncertain}
