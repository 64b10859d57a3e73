"""The service's catalog in SQLite: recordings, sweeps, jobs and campaigns, so a restart loses nothing.

One connection shared by the service's threads behind a lock (SQLite serialises writers anyway; the
queries are short). WAL mode: readers do not wait for the writer, and a killed process leaves a
consistent database. Ids are 12 lowercase hex digits, made here; an id that reaches the file system
has been checked against ID_PATTERN and looked up in the catalog first.
"""
from __future__ import annotations

import json
import re
import secrets
import sqlite3
import threading
import time
from pathlib import Path

from .text import cleaned, finite

ID_PATTERN = r"^[0-9a-f]{12}$"
_ID = re.compile(ID_PATTERN)

SCHEMA = """
CREATE TABLE IF NOT EXISTS recordings (
    id TEXT PRIMARY KEY, created REAL, origin TEXT, filename TEXT, path TEXT, status TEXT,
    sweep_id TEXT, info TEXT);
CREATE TABLE IF NOT EXISTS sweeps (
    id TEXT PRIMARY KEY, created REAL, updated REAL, state TEXT, progress REAL, request TEXT,
    recording_id TEXT, error TEXT, operator TEXT);
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY, created REAL, updated REAL, kind TEXT, recording_id TEXT, options TEXT,
    state TEXT, attempts INTEGER, error TEXT, result_dir TEXT);
CREATE TABLE IF NOT EXISTS campaigns (
    id TEXT PRIMARY KEY, created REAL, updated REAL, name TEXT, state TEXT, reason TEXT, operator TEXT,
    plan TEXT, sweeps TEXT, progress TEXT, recording_ids TEXT);
"""
#: the lists' and lookups' indices (the dashboard pages through months of recordings; every recording's
#: latest job is found by recording and kind)
INDICES = """
CREATE INDEX IF NOT EXISTS recordings_by_created ON recordings (created);
CREATE INDEX IF NOT EXISTS recordings_by_status ON recordings (status, created);
CREATE INDEX IF NOT EXISTS recordings_by_origin ON recordings (origin, created);
CREATE INDEX IF NOT EXISTS sweeps_by_created ON sweeps (created);
CREATE INDEX IF NOT EXISTS jobs_by_recording ON jobs (recording_id, kind, created);
CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs (state, created);
CREATE INDEX IF NOT EXISTS campaigns_by_created ON campaigns (created);
"""
#: columns added after the first release: (table, column, type); added to an older catalog when opened
ADDED_COLUMNS = (("recordings", "archived", "REAL"),)  # archived: when an operator archived it (None: not)
#: columns stored as JSON text, per table (a name can mean a number in one table and JSON in another)
JSON_FIELDS = {"recordings": {"info"}, "sweeps": {"request"}, "jobs": {"options"},
               "campaigns": {"plan", "sweeps", "progress", "recording_ids"}}


#: the file a job of each kind delivers, written atomically and last (server/worker.py): when it is there,
#: whole, the job's result is complete, and a re-run of the job adopts it instead of computing again
RESULT_FILES = {"identify": "model.json", "explain": "explain.json", "identify_joint": "joint.json",
                "explain_campaign": "explain.json"}


def delivered(job: dict) -> bool:
    """Whether the job's result file is there (it is never there half-written)."""
    name = RESULT_FILES.get(job.get("kind"))
    return bool(name and job.get("result_dir")) and (Path(job["result_dir"]) / name).is_file()


def new_id() -> str:
    return secrets.token_hex(6)


def valid_id(value: str) -> bool:
    return bool(_ID.match(value or ""))


class Catalog:
    def __init__(self, path):
        self.path = Path(path)
        self.db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None, timeout=10.0)
        self.db.row_factory = sqlite3.Row
        # text as served: bytes that are not UTF-8 (written by another program) read with U+FFFD, not an error
        self.db.text_factory = lambda raw: raw.decode("utf-8", "replace")
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.executescript(SCHEMA)
        for table, column, kind in ADDED_COLUMNS:
            if column not in {r[1] for r in self.db.execute(f"PRAGMA table_info({table})")}:
                try:
                    self.db.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")
                except sqlite3.OperationalError:  # the other process (web server, controller) added it first
                    pass
        self.db.executescript(INDICES)
        self.lock = threading.Lock()
        self.queries = NamedQueries(self)

    def close(self) -> None:
        with self.lock:
            self.db.close()

    # -- generic ------------------------------------------------------------------------------------
    def _row(self, table: str, row) -> dict | None:
        if row is None:
            return None
        d = dict(row)
        for k in JSON_FIELDS[table] & d.keys():
            # cleaned: a lone surrogate stored as "\ud800" by an older version must not break a listing
            d[k] = cleaned(json.loads(d[k])) if d[k] else {}
        return d

    def insert(self, table: str, **values) -> dict:
        values = {k: json.dumps(v) if k in JSON_FIELDS[table] else v for k, v in values.items()}
        cols = ", ".join(values)
        with self.lock:
            self.db.execute(f"INSERT INTO {table} ({cols}) VALUES ({', '.join('?' * len(values))})",
                            tuple(values.values()))
        return self.get(table, values["id"])

    def update(self, table: str, id: str, **values) -> None:
        if table != "recordings":
            values["updated"] = time.time()
        values = {k: json.dumps(v) if k in JSON_FIELDS[table] else v for k, v in values.items()}
        with self.lock:
            self.db.execute(f"UPDATE {table} SET {', '.join(f'{k} = ?' for k in values)} WHERE id = ?",
                            (*values.values(), id))

    def set_info(self, id: str, **keys) -> None:
        """Set top-level keys of a recording's `info` in one statement: the rig controller and the web
        server both add to it, and a read-modify-write by one would undo what the other wrote meanwhile.
        Non-finite floats are stored as null (SQLite's json() refuses NaN: a job's summary would fail)."""
        if not all(k.isidentifier() for k in keys):  # the keys are the code's (job kinds), never a client's
            raise ValueError(f"info keys must be identifiers: {list(keys)}")
        paths = ", ".join(f"'$.{k}', json(?)" for k in keys)
        with self.lock:
            self.db.execute("UPDATE recordings SET info = json_set(CASE WHEN json_valid(info) AND json_type(info) = "
                            f"'object' THEN info ELSE '{{}}' END, {paths}) WHERE id = ?",
                            (*(json.dumps(finite(v), allow_nan=False) for v in keys.values()), id))

    def delete(self, table: str, id: str) -> None:
        with self.lock:
            self.db.execute(f"DELETE FROM {table} WHERE id = ?", (id,))

    def get(self, table: str, id: str) -> dict | None:
        with self.lock:
            return self._row(table, self.db.execute(f"SELECT * FROM {table} WHERE id = ?", (id,)).fetchone())

    def list(self, table: str, where: str = "", args: tuple = (), limit: int = 200) -> list[dict]:
        sql = f"SELECT * FROM {table} {('WHERE ' + where) if where else ''} ORDER BY created DESC LIMIT ?"
        with self.lock:
            return [self._row(table, r) for r in self.db.execute(sql, (*args, limit)).fetchall()]

    def count(self, table: str, where: str = "1", args: tuple = ()) -> int:
        with self.lock:
            return int(self.db.execute(f"SELECT COUNT(*) FROM {table} WHERE {where}", args).fetchone()[0])

    # -- jobs -----------------------------------------------------------------------------------------
    def next_queued_job(self) -> dict | None:
        with self.lock:
            return self._row("jobs", self.db.execute(
                "SELECT * FROM jobs WHERE state = 'queued' ORDER BY created LIMIT 1").fetchone())

    def recover_after_restart(self, max_attempts: int = 2) -> list[str]:
        """Jobs a dead web server left running go back to the queue (or fail after max_attempts, unless
        their result was delivered: a job with a result never fails). Returns what was done, for the log. (Sweeps are the rig controller's: abort_interrupted_sweeps.)"""
        notes = []
        for job in self.list("jobs", "state = 'running'", limit=10_000):
            if delivered(job):  # its result is there, whole: the re-run adopts it (server/worker.py)
                self.update("jobs", job["id"], state="queued", error=None)
                notes.append(f"job {job['id']}: its result was delivered before the restart; re-queued to adopt it")
            elif job["attempts"] >= max_attempts:
                self.update("jobs", job["id"], state="failed",
                            error=f"interrupted {job['attempts']} times by service restarts; not retried")
                notes.append(f"job {job['id']}: failed (interrupted {job['attempts']} times)")
            else:
                self.update("jobs", job["id"], state="queued", error="interrupted by a service restart; re-queued")
                notes.append(f"job {job['id']}: re-queued after a restart")
        return notes

    def abort_interrupted_sweeps(self) -> list[str]:
        """Sweeps a dead rig controller left queued/running are marked aborted (its sweep thread is gone,
        so the PLC's watchdog stopped the table). Returns what was done, for the log."""
        notes = []
        for sweep in self.list("sweeps", "state IN ('queued', 'running')", limit=10_000):
            self.update("sweeps", sweep["id"], state="aborted",
                        error="the service stopped during the sweep (the PLC watchdog stopped the table)")
            notes.append(f"sweep {sweep['id']}: marked aborted")
        return notes


#: the dashboard's page of recordings: each with its sweep and its latest identify and explain job, in one
#: statement (the jobs found through jobs_by_recording); {where} is made by NamedQueries.recordings_where
RECORDINGS_PAGE = """
SELECT r.id, r.created, r.origin, r.filename, r.status, r.sweep_id, r.info, r.archived,
       s.state AS sweep_state, s.progress AS sweep_progress, s.error AS sweep_error, s.request AS sweep_request,
       s.operator AS sweep_operator,
       ji.id AS identify_id, ji.state AS identify_state, ji.error AS identify_error, ji.updated AS identify_updated,
       je.id AS explain_id, je.state AS explain_state, je.error AS explain_error, je.updated AS explain_updated
FROM recordings r
LEFT JOIN sweeps s ON s.id = r.sweep_id
LEFT JOIN jobs ji ON ji.id = (SELECT id FROM jobs WHERE recording_id = r.id AND kind = 'identify'
                              ORDER BY created DESC LIMIT 1)
LEFT JOIN jobs je ON je.id = (SELECT id FROM jobs WHERE recording_id = r.id AND kind = 'explain'
                              ORDER BY created DESC LIMIT 1)
WHERE {where} ORDER BY r.created DESC LIMIT ? OFFSET ?
"""
RECORDINGS_COUNT = "SELECT COUNT(*) FROM recordings r LEFT JOIN sweeps s ON s.id = r.sweep_id WHERE {where}"
#: the rig history's points: recordings with their latest identification's result folder (one statement);
#: last_identify_job is set when that job completed (JobQueue._done)
IDENTIFIED = """
SELECT r.*, j.result_dir AS result_dir FROM recordings r
JOIN jobs j ON j.id = json_extract(r.info, '$.last_identify_job')
WHERE r.archived IS NULL AND j.result_dir IS NOT NULL {only} ORDER BY r.created DESC LIMIT ?
"""
#: IDENTIFIED's restriction to the service's own rig's complete sweeps (the preflight's model: server/preflight.py)
RIG_SWEEPS = "AND r.origin = 'sweep' AND r.status = 'complete'"
#: the recordings of a campaign: every sweep it started (aborted ones too), from its `sweeps` JSON
CAMPAIGN_RECORDINGS = ("r.id IN (SELECT json_extract(c.value, '$.recording_id') FROM campaigns, "
                       "json_each(campaigns.sweeps) AS c WHERE campaigns.id = ?)")
#: what the dashboard's search looks in: id, file name, the sweep's note, who started or uploaded it
SEARCHED = ("r.id", "r.filename", "json_extract(r.info, '$.sweep.note')", "s.operator",
            "json_extract(r.info, '$.uploaded_by')")


#: complete sweep recordings with no identification job yet: what auto-identification owes (the rig
#: controller only records; the web server, the jobs table's one writer, queues their jobs)
OWED_IDENTIFY = """
SELECT r.id FROM recordings r WHERE r.origin = 'sweep' AND r.status = 'complete' AND r.archived IS NULL
AND NOT EXISTS (SELECT 1 FROM jobs j WHERE j.recording_id = r.id AND j.kind = 'identify') ORDER BY r.created
"""
#: completed campaigns of two or more complete recordings with no joint identification job yet
OWED_JOINT = """
SELECT c.id, c.recording_ids FROM campaigns c WHERE c.state = 'completed' AND json_array_length(c.recording_ids) >= 2
AND NOT EXISTS (SELECT 1 FROM jobs j WHERE j.kind = 'identify_joint' AND json_extract(j.options, '$.campaign_id') = c.id)
ORDER BY c.created
"""


class NamedQueries:
    """The catalog's composite queries, each one SQL statement (no query per listed row)."""

    def __init__(self, catalog: Catalog):
        self.catalog = catalog

    @staticmethod
    def recordings_where(since: float | None = None, until: float | None = None, origin: str | None = None,
                         status: str | None = None, campaign: str | None = None, search: str | None = None,
                         archived: bool = False) -> tuple[str, tuple]:
        """The filters as a WHERE clause and its arguments (values always as parameters)."""
        clauses, args = ["r.archived IS NOT NULL" if archived else "r.archived IS NULL"], []
        for sql, value in (("r.created >= ?", since), ("r.created < ?", until), ("r.origin = ?", origin),
                           ("r.status = ?", status), (CAMPAIGN_RECORDINGS, campaign)):
            if value is not None:
                clauses.append(sql)
                args.append(value)
        if search:
            pattern = "%" + search.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_") + "%"
            clauses.append("(" + " OR ".join(f"{col} LIKE ? ESCAPE '\\'" for col in SEARCHED) + ")")
            args += [pattern] * len(SEARCHED)
        return " AND ".join(clauses), tuple(args)

    def recordings_page(self, offset: int = 0, limit: int = 50, **filters) -> tuple[list[dict], int]:
        """A page of recordings, newest first, with their sweep and latest jobs; and how many match."""
        where, args = self.recordings_where(**filters)
        cat = self.catalog
        with cat.lock:
            total = int(cat.db.execute(RECORDINGS_COUNT.format(where=where), args).fetchone()[0])
            rows = cat.db.execute(RECORDINGS_PAGE.format(where=where), (*args, limit, offset)).fetchall()
        return [_page_row(dict(r)) for r in rows], total

    def recording(self, rec_id: str) -> dict | None:
        """One recording as recordings_page shows it (archived or not)."""
        with self.catalog.lock:
            row = self.catalog.db.execute(RECORDINGS_PAGE.format(where="r.id = ?"), (rec_id, 1, 0)).fetchone()
        return None if row is None else _page_row(dict(row))

    def owed_jobs(self) -> list[tuple[str, str, dict]]:
        """(kind, recording id, options) of every job auto-identification owes: each complete sweep
        recording's `identify`, each completed campaign's `identify_joint` (its first recording, options
        naming all, in plan order)."""
        with self.catalog.lock:
            single = [r[0] for r in self.catalog.db.execute(OWED_IDENTIFY).fetchall()]
            joint = [(r[0], json.loads(r[1])) for r in self.catalog.db.execute(OWED_JOINT).fetchall()]
        return ([("identify", rec_id, {}) for rec_id in single]
                + [("identify_joint", ids[0], {"recording_ids": ids, "campaign_id": cid}) for cid, ids in joint])

    def identified(self, limit: int = 200, rig_sweeps: bool = False) -> list[tuple[dict, str]]:
        """The newest `limit` recordings (not archived) with an identification, and its result folder;
        rig_sweeps: only complete sweeps of the service's rig (no uploads)."""
        with self.catalog.lock:
            only = RIG_SWEEPS if rig_sweeps else ""
            rows = self.catalog.db.execute(IDENTIFIED.format(only=only), (limit,)).fetchall()
        recs = [self.catalog._row("recordings", r) for r in rows]
        return [(rec, rec.pop("result_dir")) for rec in recs]


def _page_row(row: dict) -> dict:
    """A RECORDINGS_PAGE row as the dashboard shows a recording: its sweep and its jobs nested."""
    rec = {k: row[k] for k in ("id", "created", "origin", "filename", "status", "sweep_id", "archived")}
    rec["info"] = json.loads(row["info"]) if row["info"] else {}
    rec["sweep"] = None if row["sweep_state"] is None else {
        "state": row["sweep_state"], "progress": row["sweep_progress"], "error": row["sweep_error"],
        "request": json.loads(row["sweep_request"]) if row["sweep_request"] else {}, "operator": row["sweep_operator"]}
    rec["jobs"] = {kind: {"state": "none"} if row[f"{kind}_id"] is None else
                   {"state": row[f"{kind}_state"], "id": row[f"{kind}_id"], "error": row[f"{kind}_error"],
                    "updated": row[f"{kind}_updated"]} for kind in ("identify", "explain")}
    return cleaned(rec)  # as _row: stored text never breaks the page
