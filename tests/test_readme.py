"""README.md's commands, run as written, in order, in a copy of the repository as a fresh clone has it.

Every fenced ```sh and ```python block of README.md is run; nothing is rewritten except what a fresh clone
cannot do inside this suite, handled here by name:

- `make demo` runs with the environment's stamp taken as up to date (`make -o .venv/.installed demo`):
  the copy's `.venv` is this suite's environment (a link), which must not be rebuilt under it;
- `make test` is not run: this test is part of it;
- a command whose comment says "(runs until Ctrl-C)" (`shakeid serve`, `shakeid sim`) is started in the
  background, waited for until its ports answer, and stopped when its block and the block after it (the
  README's "in a second terminal") are done: with SIGTERM, as a supervisor stops it (a script's background
  job ignores SIGINT, so Ctrl-C cannot be sent; both commands end the same way on either).

Then: each command succeeded (the script stops at the first failure and names it), what the README says
the commands leave is there, and nothing they wrote is left for git to pick up (.gitignore covers it).
"""
from __future__ import annotations
import pytest

import fcntl
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import zipfile
from pathlib import Path

import h5py

REPO = Path(__file__).resolve().parents[1]
#: commands that run until Ctrl-C, and the TCP ports that answer once they are ready
LONG_RUNNING = {"shakeid serve": (8000,), "shakeid sim": (5020, 5021)}
MAKE = {"make demo": "make -o .venv/.installed demo", "make test": None}  # None: not run (see above)
BLOCK = re.compile(r"^```(sh|python)\n(.*?)^```", re.M | re.S)


def readme_blocks(text: str) -> list[tuple[str, list[str]]]:
    """[(language, commands)]: sh blocks as logical lines (backslash continuations joined, comment-only
    lines dropped); a python block as one piece of source."""
    out = []
    for lang, body in BLOCK.findall(text):
        if lang == "python":
            out.append((lang, [body]))
            continue
        lines, cur = [], ""
        for raw in body.splitlines():
            if not cur and (not raw.strip() or raw.lstrip().startswith("#")):
                continue
            cur += raw.strip() if cur else raw.rstrip()
            if cur.endswith("\\"):
                cur = cur[:-1].rstrip() + " "
                continue
            lines.append(cur)
            cur = ""
        out.append((lang, lines))
    return out


def _strip_comment(line: str) -> str:
    """The line without its trailing comment: from the first # outside quotes that starts a word."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip()
    return line.rstrip()


def _command(line: str) -> str:
    """The command as one normalised string, for matching and for the log."""
    return " ".join(_strip_comment(line).split())


def script(blocks, python: str) -> str:
    """One bash script running the blocks in order; background commands started, waited for, stopped."""
    out = ["set -eo pipefail", "trap 'for p in $BG; do kill -TERM $p 2>/dev/null; done' EXIT", "BG=''",
           'wait_ports() { for i in $(seq 600); do ok=1; for port in "$@"; do '
           '(exec 3<>/dev/tcp/127.0.0.1/$port) 2>/dev/null || ok=0; done; '
           '[ $ok = 1 ] && return 0; sleep 0.1; done; echo "ports $* never answered"; return 1; }',
           'stop() { kill -TERM $1; for i in $(seq 200); do kill -0 $1 2>/dev/null || { wait $1 || true; return 0; }; '
           'sleep 0.1; done; echo "pid $1 did not stop on SIGTERM"; kill -KILL $1; return 1; }']
    pending: list[str] = []  # background pids of the previous block, stopped after this one
    for n, (lang, commands) in enumerate(blocks):
        started = []
        if lang == "python":
            out += [f"echo '+ README python block {n}'", f"{shlex.quote(python)} - <<'README_PY'", commands[0],
                    "README_PY"]
        for line in commands if lang == "sh" else []:
            cmd = _command(line)
            if cmd.startswith("make "):
                if cmd not in MAKE:
                    raise AssertionError(f"README runs {cmd!r}: say in tests/test_readme.py how to run it here")
                if MAKE[cmd] is None:
                    continue
                out += [f"echo \"+ [$SECONDS s] \"{shlex.quote(cmd)}", MAKE[cmd]]
                continue
            long = next((k for k in LONG_RUNNING if cmd.startswith(k + " ") or cmd == k), None)
            if long:
                assert "runs until Ctrl-C" in line, f"{cmd!r} does not say it runs until Ctrl-C"
                pid, log = f"$PID_{n}_{len(started)}", f"../bg-{n}-{len(started)}.log"
                out += [f"echo {shlex.quote('+ ' + cmd + ' &')}", f"{_strip_comment(line)} > {log} 2>&1 &", f"{pid[1:]}=$!",
                        f'BG="$BG {pid}"', f"wait_ports {' '.join(map(str, LONG_RUNNING[long]))} || "
                                           f"{{ cat {log}; exit 1; }}"]
                started.append(pid)
                continue
            out += [f"echo \"+ [$SECONDS s] \"{shlex.quote(cmd)}", line]
        for pid in pending:
            out += [f"stop {pid}", f'BG="${{BG/{pid}/}}"']
        pending = started
    for pid in pending:
        out.append(f"stop {pid}")
    return "\n".join(out) + "\n"


def _fresh_copy(dest: Path) -> None:
    """What a clone has: tracked files and new ones git does not ignore; no build products, no .venv."""
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, files):
        src = REPO / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            (dest / name).write_bytes(src.read_bytes())
    subprocess.run(["git", "init", "-q"], cwd=dest, check=True)
    subprocess.run(["git", "add", "-A"], cwd=dest, check=True)


def test_readme_parser_reads_continuations_and_comments():
    """The extraction the test below relies on: a continued line is one command, its comment kept."""
    text = "x\n```sh\n# a note\nshakeid a --b 1 \\\n    --c 2   # says what\n\nshakeid d\n```\n```text\nno\n```\n"
    assert readme_blocks(text) == [("sh", ["shakeid a --b 1 --c 2   # says what", "shakeid d"])]
    assert _command("shakeid a --b 1 --c 2   # says what") == "shakeid a --b 1 --c 2"
    assert _strip_comment("shakeid x --extra-terms 'a#b' # c") == "shakeid x --extra-terms 'a#b'"


@pytest.mark.slow
def test_every_readme_command_runs_verbatim(tmp_path):
    blocks = readme_blocks((REPO / "README.md").read_text())
    assert sum(len(c) for lang, c in blocks if lang == "sh") >= 20  # the README's commands, all found
    clone = tmp_path / "clone"
    clone.mkdir()
    _fresh_copy(clone)
    (clone / ".venv").symlink_to(Path(sys.prefix))  # what `make venv` leaves, without building it again
    venv_bin = str(Path(sys.prefix) / "bin")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SHAKEID_") and k != "VIRTUAL_ENV"}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if p != venv_bin)  # as a new shell
    (tmp_path / "readme.sh").write_text(script(blocks, "python"))
    # the README's fixed ports (8000, 5020, 5021): one README run at a time on this machine
    with open(Path("/tmp") / "shakeid-readme-test.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.Popen(["bash", str(tmp_path / "readme.sh")], cwd=clone, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, start_new_session=True)
        try:
            output, _ = proc.communicate(timeout=900)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the script's own process group: its commands, nothing else
            output, _ = proc.communicate()
            raise AssertionError("README commands did not finish in 900 s:\n" + output[-4000:]) from None
    print(output)  # with -s: each command and when it started ([s] since the start)
    assert proc.returncode == 0, "a README command failed (the last '+' line):\n" + output[-6000:]
    # what the README says the commands leave
    for page in ("demo-output/report/index.html", "report/index.html", "explain/index.html"):
        assert "<table>" in (clone / page).read_text(), page
    assert json.loads((clone / "models" / "batch.json").read_text())
    # `shakeid frf ... --report frf/` and `shakeid export ... --format fmu`
    assert (clone / "frf" / "frf.png").stat().st_size > 0 and "jump" in (clone / "frf" / "index.html").read_text()
    with zipfile.ZipFile(clone / "sweep.fmu") as fmu:
        assert "modelDescription.xml" in fmu.namelist()
    # `shakeid batch sweep.csv sweep.h5`: two recordings, two models (not one file written twice)
    assert sorted(p.name for p in (clone / "models").iterdir()) == ["batch.json", "sweep.csv.model.json",
                                                                    "sweep.h5.model.json"]
    assert "identified beside the simulated rig's true model" in output  # the demo's comparison
    # `shakeid explain sweep.csv`: the simulated rig's one hidden effect (sweep.truth.json), and nothing else
    # (a spurious second effect, a channel delay of 0.04 samples, sits at the edge of the acceptance rule:
    # docs/identification.md section 7); `shakeid explain sweep.csv down.csv`: the same, once, over both sweeps
    assert output.count("missing effect: displacement_dependent_damping") == output.count("missing effect:") == 2
    assert "2 recordings explained together" in output
    with h5py.File(clone / "sweep.h5") as f:
        assert f["entry"].attrs["status"] == "complete" and "processed" in f["entry"]
    assert len(list((clone / "levels").glob("quick-*.h5"))) == 2
    # the second `identify ... --report report/` (of sweep.h5) says it replaced the first (of sweep.csv)
    assert "report: report/index.html (replaces the report written there at 20" in output
    assert "free-run fit" in output and "sweep 100 %" in output  # the service's sweep printed its model
    # nothing the commands wrote is left for git (the .venv link is this test's, not the README's)
    status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=clone,
                            capture_output=True, text=True, check=True).stdout.splitlines()
    assert [s for s in status if s.startswith("??") and s != "?? .venv"] == []
