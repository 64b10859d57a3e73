"""The explain JSON against its schema (docs/schemas/explanation.schema.json), on real outputs of the CLI:
every field the schema lists is there, nothing undocumented is, and the gap closed has one definition."""
import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from identify.data.recording import write_csv
from sim.rig import RigParameters
from protocol.sweep import SineSweep
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

SCHEMA = json.loads((Path(__file__).resolve().parents[2] / "docs" / "schemas" / "explanation.schema.json").read_text())


@pytest.mark.parametrize("effects", [{"coulomb_friction": 0.1}, {}])
def test_explain_json_matches_its_schema(make_run, tmp_path, effects):
    run = make_run(rig=RigParameters.design(effects=effects), sweep=SineSweep(1.0, 20.0, 20.0, 1.3), fs_hz=1000.0,
                   seed=5)
    path = tmp_path / "rec.csv"
    write_csv(path, run.recording)
    exe = str(Path(sys.executable).with_name("shakeid"))
    proc = subprocess.run([exe, "explain", str(path), "--json"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    jsonschema.Draft202012Validator(SCHEMA).validate(doc)
    assert "noise_floor_upper" not in doc and "data_quality" in doc
    # one definition of the gap closed: the top level's and each effect's are 1 - after / before
    assert doc["gap_closed"] == pytest.approx(1 - doc["gap_after"] / doc["gap_before"])
    before = doc["gap_before"]
    for e in doc["effects"]:
        assert e["gap_closed"] == pytest.approx(1 - e["gap_after"] / before)
        assert e["gap_share_closed"] == pytest.approx(1 - (1 - e["gap_closed"]) ** 2)
        before = e["gap_after"]
    if effects:
        assert doc["effect"] == "coulomb_friction"
    else:
        assert doc["effect"] == "none" and doc["confidence"] >= 0.5
