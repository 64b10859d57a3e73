"""The frequency response beside the measured sweeps on the dashboard, in a real browser against a real
`shakeid serve` (simulated rig at 10x): a sweep's recording page shows its section (the jump table as
GET /api/recordings/{id}/frf gives it, the overlay image loaded, frf.json opening); a campaign's page
(reached from the campaigns table) shows the joint model's overlay at every table amplitude, its sweeps
link to their recordings, and its frf.json opens."""
from __future__ import annotations

import json

import pytest

from .conftest import Service, wait_for, wait_for_job
from .test_dashboard import TIMEOUT_MS, browser, identified, page, sweep_body, wait_idle  # noqa: F401 (fixtures)
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    s = Service(tmp_path_factory.mktemp("frf") / "data", speed=10.0).start()
    yield s
    s.stop()


def images_loaded(pg, selector: str, n: int = 1) -> bool:
    return pg.evaluate(f"[...document.querySelectorAll({json.dumps(selector)})].filter(i => i.naturalWidth > 0).length >= {n}")


def popup_json(pg, selector: str):
    """The document a link opens in a new tab (a blob: address made from the API's answer)."""
    with pg.expect_popup() as popup:
        pg.click(selector)
    tab = popup.value
    tab.wait_for_url("blob:**")
    tab.wait_for_load_state()
    doc = json.loads(tab.evaluate("(document.querySelector('pre') || document.body).innerText"))
    tab.close()
    return doc


def shown_rows(pg, selector: str) -> list[list[str]]:
    return [r.split("\t") for r in pg.locator(f"{selector} tr").all_inner_texts()[1:]]


def test_recording_page_shows_the_overlay(page, service):  # noqa: F811
    with service.client() as api:
        wait_idle(api)
        sweep_id = api.post("/api/sweeps", json=sweep_body(30.0, amplitude_mm=1.2)).json()["id"]
        sweep = wait_for(lambda: (s := api.get(f"/api/sweeps/{sweep_id}").json())["state"] == "completed" and s,
                         what="the sweep")
        rec = identified(api, sweep["recording_id"])
        frf = api.get(f"/api/recordings/{rec['id']}/frf").json()
        model = api.get(f"/api/recordings/{rec['id']}/model").json()
        plots = api.get(f"/api/recordings/{rec['id']}/plots").json()
    # what the service stored: one table amplitude, the recorded one; the up-sweep's jump measured and judged
    assert frf["status"] == "ok", frf
    assert model["frf"] == frf  # model.json carries the same document as frf.json
    # seen once in a full `make test` (2026-11-29, not reproduced): 1.049 mm for the 1.2 mm asked; most likely
    # the median of every table cycle, the rest's noise around the sweep among them (identify.frf.measured.
    # steady_cycles now, tests/identify/test_frf_measured.py); the message keeps the sweep and the recording
    assert [a["amplitude_mm"] for a in frf["amplitudes"]] == [pytest.approx(1.2, rel=0.03)], \
        {"frf_amplitudes_mm": [a["amplitude_mm"] for a in frf["amplitudes"]], "sweep": sweep,
         "recording": {k: v for k, v in rec.items() if k not in ("model",)}}
    assert [j["direction"] for j in frf["jumps"]] == ["up"] and frf["jumps"][0]["measured_hz"] is not None
    assert "frf_overlay.png" in plots
    page.goto(f"{service.url}/#/recording/{rec['id']}")
    page.wait_for_selector("#rec-frf-jumps")
    rows = shown_rows(page, "#rec-frf-jumps")
    assert len(rows) == len(frf["jumps"])
    j = frf["jumps"][0]
    assert rows[0][2] == f"{j['measured_hz']:.3f} ± {j['uncertainty_hz']:.3f}"
    assert rows[0][4] == ("–" if j["predicted"]["model"]["fold_hz"] is None else f"{j['predicted']['model']['fold_hz']:.3f}")
    assert rows[0][7] == ("agrees" if j["predicted"]["model"]["agrees"] else "misses")
    assert ("flagged" in page.inner_text("#rec-frf-flags")) == frf["flagged"]
    wait_for(lambda: images_loaded(page, "#rec-frf-figure img"), 30, "the overlay image")
    # the overlay is in its own section, not again among the report's figures
    assert page.locator("#rec-model-figures img[alt='frf_overlay.png']").count() == 0
    assert popup_json(page, "#rec-frf-json") == frf


def test_campaign_builder_proposes_from_the_model(page, service):  # noqa: F811
    """The builder's "propose from the model" fills the campaign's fields with POST /api/campaigns/proposal's
    plan (the rig's latest model: the recording identified above), which brackets its predicted jumps."""
    page.fill("#c-name", "frf-proposed")
    page.click("#c-propose")
    page.locator(".msg", has_text="proposed from").wait_for(timeout=240_000)
    with service.client() as api:
        # computed once: the page's request finished it, so this one answers at once (200, not 202)
        answer = api.post("/api/campaigns/proposal", json={"name": "frf-proposed"}, timeout=60)
        assert answer.status_code == 200, answer.text
        proposal = answer.json()
        refused = api.post("/api/campaigns/proposal", json={"recording_id": "000000000000"})
    plan, sweep = proposal["plan"], proposal["plan"]["sweep"]
    assert [float(a) for a in page.input_value("#c-amps").split(",")] == plan["amplitudes_mm"]
    assert [float(page.input_value(f"#c-{k}")) for k in ("f0", "f1", "dur")] == \
        [sweep["f_start_hz"], sweep["f_end_hz"], sweep["duration_s"]]
    assert page.is_checked("#c-up") and page.is_checked("#c-down")
    folding = [a for a in proposal["amplitudes"] if a["jump_down_hz"] is not None]
    assert len(folding) == 2 and proposal["amplitudes"][0]["jump_down_hz"] is None
    for a in folding:
        assert sweep["f_start_hz"] < a["jump_up_hz"] <= a["jump_down_hz"] < sweep["f_end_hz"]
    assert refused.status_code == 404 and "no recording 000000000000" in refused.json()["detail"]


def test_campaign_page_shows_every_amplitude(page, service):  # noqa: F811
    with service.client() as api:
        wait_idle(api)
        plan = {"name": "frf-levels", "amplitudes_mm": [0.8, 1.2], "directions": ["up"],
                "sweep": {"f_start_hz": 1.0, "f_end_hz": 20.0, "duration_s": 30.0, "settle_s": 0.5}}
        cid = api.post("/api/campaigns", json=plan).json()["id"]
        joint = wait_for(lambda: ((c := api.get(f"/api/campaigns/{cid}").json())["joint_identification"] or {})
                         .get("state") in ("completed", "failed") and c["joint_identification"], 240, "the joint model")
        assert joint["state"] == "completed", joint
        truth = api.get(f"/api/campaigns/{cid}").json()
        frf = api.get(f"/api/campaigns/{cid}/frf").json()
        figure = api.get(f"/api/campaigns/{cid}/frf.png")
    assert frf["status"] == "ok", frf
    assert [a["amplitude_mm"] for a in frf["amplitudes"]] == [pytest.approx(0.8, rel=0.03), pytest.approx(1.2, rel=0.03)]
    assert figure.status_code == 200 and figure.content.startswith(b"\x89PNG")
    # from the campaigns table to the campaign's page
    page.goto(f"{service.url}/#")
    page.click(f"#campaigns tr[data-id='{cid}'] a[href='#/campaign/{cid}']")
    page.wait_for_selector("#camp-frf-jumps")
    assert len(shown_rows(page, "#camp-frf-jumps")) == len(frf["jumps"]) == 2
    wait_for(lambda: images_loaded(page, "#camp-frf-figure img"), 30, "the campaign's overlay image")
    assert popup_json(page, "#camp-frf-json") == frf
    # each sweep links to its recording's page
    for rec_id in truth["recording_ids"]:
        assert page.locator(f"#camp-sweeps a[href='#/recording/{rec_id}']").count() == 1
    page.click(f"#camp-sweeps a[href='#/recording/{truth['recording_ids'][0]}']")
    page.wait_for_selector("#recording:not([hidden]) #rec-body")
    assert page.locator("#campaign").is_hidden()
    page.go_back()
    page.wait_for_selector("#camp-frf-jumps")
    # the operator asks for one explanation over both sweeps from the campaign's page (POST
    # /api/campaigns/{id}/explain); the page follows the job and shows the same answer the API serves
    page.click("#camp-explain-go")
    with service.client() as api:  # the job behind the recordings' own: waited for while the queue moves
        wait_for(lambda: api.get(f"/api/campaigns/{cid}").json()["explanation"], 30, "the explanation job")
        job = wait_for_job(api, lambda: api.get(f"/api/campaigns/{cid}").json()["explanation"], what="the explanation")
    assert job["state"] == "completed", job["error"]
    page.wait_for_selector("#camp-effect")  # the page follows the job (every 2 s while it runs)
    with service.client() as api:
        doc = api.get(f"/api/campaigns/{cid}/explanation").json()
    text = page.inner_text("#camp-effect")
    assert [r["source"] for r in doc["recordings"]] and len(doc["recordings"]) == 2, doc.get("recordings")
    assert "over 2 recordings together" in text
    assert (doc["effect"] or "no effect").replace("_", " ") in text.replace("no effect found", "no effect")
    assert page.locator("#camp-explain-go").inner_text() == "explain again"
