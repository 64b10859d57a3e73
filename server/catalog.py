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
#: columns stored as JSON text, per table (a name can mean a number in one table and JSON in another)
JSON_FIELDS = {"recordings": {"info"}, "sweeps": {"request"}, "jobs": {"options"},
               "campaigns": {"plan", "sweeps", "progress", "recording_ids"}}


def new_id() -> str:
    return secrets.token_hex(6)


def valid_id(value: str) -> bool:
    return bool(_ID.match(value or ""))


class Catalog:
    def __init__(self, path):
        self.path = Path(path)
        self.db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None, timeout=10.0)
        self.db.row_factory = sqlite3.Row
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.executescript(SCHEMA)
        self.lock = threading.Lock()

    def close(self) -> None:
        with self.lock:
            self.db.close()

    # -- generic ------------------------------------------------------------------------------------
    def _row(self, table: str, row) -> dict | None:
        if row is None:
            return None
        d = dict(row)
        for k in JSON_FIELDS[table] & d.keys():
            d[k] = json.loads(d[k]) if d[k] else {}
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
        """Jobs a dead web server left running go back to the queue (or fail after max_attempts).
        Returns what was done, for the log. (Sweeps are the rig controller's: abort_interrupted_sweeps.)"""
        notes = []
        for job in self.list("jobs", "state = 'running'", limit=10_000):
            if job["attempts"] >= max_attempts:
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
