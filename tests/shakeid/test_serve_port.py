"""`shakeid serve` on a port something already listens on: one line naming the port and what to do, exit 2,
before any banner or token is printed (uvicorn's own bind error came after them, exit 3)."""
import socket
import subprocess
import sys
from pathlib import Path


def test_a_busy_port_is_refused_before_the_banner(tmp_path):
    with socket.socket() as other:
        other.bind(("127.0.0.1", 0))
        other.listen()
        port = other.getsockname()[1]
        run = subprocess.run([str(Path(sys.executable).with_name("shakeid")), "serve", "--port", str(port),
                              "--data-dir", str(tmp_path / "data")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run
    assert run.stdout == "" and "token" not in run.stderr
    assert f"cannot serve on 127.0.0.1:{port}: address already in use" in run.stderr
    assert "--port" in run.stderr and "Traceback" not in run.stderr
