"""Text that is not text (a lone UTF-16 surrogate, a control character) in any string field of any JSON
body: 422 naming the field, nothing stored; text an older version stored never breaks a listing."""
import pytest
import json
import sqlite3
import time

from server.catalog import Catalog

from .conftest import Service

BAD_TEXTS = ("\ud800", "ok\udfff", "a\x00b", "\x1b[31m")


def _string_fields(schema: dict, doc: dict, loc: tuple = (), depth: int = 0):
    """Paths (keys, list index 0) to every string in a JSON schema of the OpenAPI document."""
    if depth > 6:
        return
    if "$ref" in schema:
        schema = doc["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    for alt in schema.get("anyOf", []) + schema.get("oneOf", []) + schema.get("allOf", []):
        yield from _string_fields(alt, doc, loc, depth + 1)
    if schema.get("type") == "string":
        yield loc
    if schema.get("type") == "array" and isinstance(schema.get("items"), dict):
        yield from _string_fields(schema["items"], doc, (*loc, 0), depth + 1)
    for name, sub in (schema.get("properties") or {}).items():
        yield from _string_fields(sub, doc, (*loc, name), depth + 1)


def _body_with(loc: tuple, bad: str):
    """A body holding `bad` at loc (the rest of the body need not be valid: the text is checked first)."""
    value = bad
    for key in reversed(loc):
        value = [value] if key == 0 else {key: value}
    return value


@pytest.mark.slow
def test_invalid_text_in_every_string_field_of_every_body_is_refused_and_nothing_is_stored(service):
    with service.client() as op:
        doc = op.get("/openapi.json").json()
        sent = 0
        for path, ops in doc["paths"].items():
            for method, spec in ops.items():
                schema = (spec.get("requestBody") or {}).get("content", {}).get("application/json", {}).get("schema")
                if schema is None:
                    continue
                url = path.replace("{rec_id}", "0123456789ab").replace("{campaign_id}", "0123456789ab") \
                          .replace("{action}", "pause").replace("{sweep_id}", "0123456789ab")
                fields = sorted(set(_string_fields(schema, doc)), key=str)
                assert fields, path
                for loc in fields:
                    for bad in BAD_TEXTS:
                        body = json.dumps(_body_with(loc, bad))  # ensure_ascii: "\ud800" travels as an escape
                        r = op.request(method.upper(), url, content=body, headers={"Content-Type": "application/json"})
                        sent += 1
                        assert r.status_code == 422, (method, url, body, r.status_code, r.text)
                        err = r.json()["detail"][0]
                        assert err["type"] == "invalid_text" and err["loc"] == ["body", *loc], (url, body, err)
                        assert "is not valid text" in err["msg"]
        assert sent > 40, sent
        for listing in ("/api/jobs", "/api/recordings", "/api/sweeps", "/api/campaigns"):
            r = op.get(listing)
            assert r.status_code == 200 and r.json() == [], (listing, r.text)
    assert "Traceback" not in service.output()


def test_text_stored_by_an_older_version_never_breaks_a_listing(tmp_path):
    """A job stored with a lone surrogate in its options (as JSON's escape) and a recording whose file name
    is not UTF-8 (written by another program): listed with U+FFFD in their place, encodable as UTF-8."""
    cat = Catalog(tmp_path / "catalog.sqlite")
    cat.insert("jobs", id="0000000000aa", created=time.time(), updated=time.time(), kind="identify",
               recording_id="0000000000bb", options={"extra_terms": ["q1\ud800"]}, state="queued", attempts=0,
               error=None, result_dir=str(tmp_path))
    db = sqlite3.connect(tmp_path / "catalog.sqlite")
    db.execute("INSERT INTO recordings (id, created, origin, filename, path, status, info) "
               "VALUES (?, ?, ?, CAST(? AS TEXT), ?, ?, ?)",
               ("0000000000bb", time.time(), "upload", b"r\xff.csv", "/x", "complete", "{}"))
    db.commit()
    db.close()
    jobs, recs = cat.list("jobs"), cat.list("recordings")
    assert jobs[0]["options"]["extra_terms"] == ["q1\ufffd"]
    assert recs[0]["filename"] == "r\ufffd.csv"
    json.dumps([jobs, recs], ensure_ascii=False).encode("utf-8")  # what a response does: no UnicodeEncodeError
    cat.close()


@pytest.mark.slow
def test_listings_stay_200_over_a_catalog_with_bad_text(tmp_path):
    """The same bad rows in a real service's catalog: every listing answers 200."""
    data = tmp_path / "data"
    data.mkdir()
    test_text_stored_by_an_older_version_never_breaks_a_listing(data)
    service = Service(data)
    try:
        service.start()
        with service.client() as op:
            for listing in ("/api/jobs", "/api/recordings", "/api/dashboard/recordings"):
                r = op.get(listing)
                assert r.status_code == 200, (listing, r.text)
    finally:
        service.stop()
