"""The dashboard shows the preflight's prediction (issue 31 item 5) in a real browser (test_dashboard's Chromium
and service): a refusal with the predicted peak, a warning kept as a message and on the sweep's line."""
from __future__ import annotations
import pytest

from .conftest import wait_for
from .test_dashboard import browser, fill_sweep, page, service, wait_idle  # noqa: F401 (fixtures)
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


def test_the_page_shows_the_refusal_and_the_warning(page, service):  # noqa: F811
    with service.client() as api:
        wait_idle(api)
        fill_sweep(page, 300.0)  # 1.3 mm: the mass would hit the end stops
        page.click("#start")
        page.locator(".msg.error", has_text="the mass would hit the end stops: predicted relative travel reaches "
                                             "the 17.5 mm travel at 6.").wait_for()
        assert api.get("/api/sweeps").json() == []
        fill_sweep(page, 60.0)  # the paper's standard sweep: 98 % of the travel
        page.click("#start")
        page.locator(".msg.warn", has_text="preflight warning: predicted relative travel 17.1 mm at 6.4").wait_for()
        page.locator("#sweep-status", has_text="98 % of the end-stop travel 17.5 mm").wait_for()
        running = api.get("/api/sweeps").json()[0]["id"]
        assert api.post(f"/api/sweeps/{running}/abort").status_code == 202
        wait_for(lambda: api.get("/api/rig").json()["active_sweep"] is None, what="the sweep aborted")
