"""GET /api/recordings/{id}/model.fmu (.c, .py, .tex): a recording's identified model as the files `shakeid
export` writes, through a real service; the FMU checked by FMPy against shakeid's free run of that model; the
recording page's buttons download them in a real browser (Debian's Chromium, as tests/server/test_dashboard.py)."""
import io
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from identify.model import SparseModel
from identify.simulation.simulate import choose_substeps, simulate

from .conftest import OPERATOR, VIEWER, Service, wait_for
from .test_dashboard import CHROMIUM, CHROMIUM_ARGS, TIMEOUT_MS
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    s = Service(tmp_path_factory.mktemp("export") / "data").start()
    yield s
    s.stop()


@pytest.fixture(scope="module")
def identified(service, tmp_path_factory, make_run):
    """An uploaded Table 1 recording (30 s sweep at 1 kHz), identified: (recording id, its model as served)."""
    import httpx

    from identify.data.recording import write_csv
    from protocol.sweep import SineSweep

    op, viewer = service.client(), service.client(VIEWER)
    csv = tmp_path_factory.mktemp("csv") / "sweep.csv"
    write_csv(csv, make_run(sweep=SineSweep(duration_s=30.0), fs_hz=1000.0).recording)
    with httpx.Client(base_url=service.url, headers={"Authorization": f"Bearer {OPERATOR}"}, timeout=120) as up:
        rec = up.post("/api/recordings", params={"filename": "sweep.csv"}, content=csv.read_bytes()).json()
    missing = viewer.get(f"/api/recordings/{rec['id']}/model.fmu")  # not identified yet: 404 saying so
    assert missing.status_code == 404 and "none was asked for" in missing.json()["detail"]
    job = op.post(f"/api/recordings/{rec['id']}/identify", json={}).json()
    done = wait_for(lambda: (j := viewer.get(f"/api/jobs/{job['id']}").json())["state"] in ("completed", "failed") and j,
                    120, "identification")
    assert done["state"] == "completed", done
    return rec["id"], SparseModel.from_dict(viewer.get(f"/api/recordings/{rec['id']}/model").json())


@pytest.mark.slow
def test_a_recordings_model_downloads_in_every_format(service, identified, tmp_path):
    rec_id, model = identified
    viewer = service.client(VIEWER)
    r = viewer.get(f"/api/recordings/{rec_id}/model.fmu")
    assert r.status_code == 200 and r.headers["content-disposition"] == f'attachment; filename="model_{rec_id}.fmu"'
    fmu = tmp_path / "model.fmu"
    fmu.write_bytes(r.content)
    names = zipfile.ZipFile(io.BytesIO(r.content)).namelist()
    assert {"modelDescription.xml", "sources/model.c", "sources/fmi2_cs.c"} <= set(names)
    assert any(n.startswith("binaries/linux64/") for n in names)
    assert validate_fmu(str(fmu)) == []
    seed = np.random.SeedSequence().entropy
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    dt, n, w = 1e-3, 2001, 2 * np.pi * 5.0
    u = -rng.uniform(1.0e-3, 1.5e-3) * w**2 * np.sin(w * np.arange(n) * dt + rng.uniform(0, 2 * np.pi))
    signals = np.zeros(n, dtype=[("time", float), ("zdd", float)])
    signals["time"], signals["zdd"] = np.arange(n) * dt, u
    res = simulate_fmu(str(fmu), input=signals, output=["q1", "q2"], stop_time=(n - 1) * dt, output_interval=dt)
    s = choose_substeps(model, dt, [0.5, 0.02])
    x, ref = np.zeros(2), [np.zeros(2)]
    for uk in u[:-1]:  # shakeid's free run of the input the FMU holds over each 1 ms step
        x = simulate(model, dt, x, inputs_fine=np.full((2 * s + 1, 1), uk), substeps=s, n_samples=2).states[1]
        ref.append(x)
    ref = np.array(ref)
    got = np.column_stack([res["q1"], res["q2"]])
    assert np.all(np.sqrt(np.mean((got - ref) ** 2, axis=0)) / np.sqrt(np.mean(ref**2, axis=0)) < 1e-4)

    c = viewer.get(f"/api/recordings/{rec_id}/model.c")
    assert c.status_code == 200 and c.headers["content-type"].startswith("text/x-csrc")
    assert "void shakeid_rk4_step(" in c.text and repr(model.equations["q1_dot"]["q2^3"]) in c.text
    py = viewer.get(f"/api/recordings/{rec_id}/model.py")
    ns: dict = {}
    exec(compile(py.text, "model.py", "exec"), ns)
    q, zdd = np.array([[0.1, 0.005], [-0.2, -0.01]]), np.array([3.0, -4.0])
    np.testing.assert_allclose(ns["rhs"](q, zdd), model.rhs(q, zdd[:, None]), rtol=1e-12)
    tex = viewer.get(f"/api/recordings/{rec_id}/model.tex")
    assert tex.status_code == 200 and r"\dot{q}_{1} &=" in tex.text and r"q_{1} q_{2}^{2}" in tex.text
    assert viewer.get(f"/api/recordings/{rec_id}/model.docx").status_code == 422  # formats are checked
    assert service.client(None).get(f"/api/recordings/{rec_id}/model.fmu").status_code == 401


@pytest.mark.slow
def test_the_recording_page_downloads_the_fmu_and_the_latex(service, identified):
    from playwright.sync_api import sync_playwright

    rec_id, _ = identified
    with service.client() as api:
        tex = api.get(f"/api/recordings/{rec_id}/model.tex").text
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_context(accept_downloads=True).new_page()
        page.set_default_timeout(TIMEOUT_MS)
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{service.url}/#token={OPERATOR}")
        page.click(f"#recs a[href='#/recording/{rec_id}']")
        page.wait_for_selector("#rec-export")
        with page.expect_download() as fmu:
            page.click("#rec-export button[data-export='fmu']")
        assert fmu.value.suggested_filename == f"model_{rec_id}.fmu"
        assert validate_fmu(fmu.value.path()) == []
        with page.expect_download() as latex:
            page.click("#rec-export button[data-export='tex']")
        assert Path(latex.value.path()).read_text() == tex
        browser.close()
    assert not errors, errors
