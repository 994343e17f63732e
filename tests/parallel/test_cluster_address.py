"""The same command line against a running cluster: ``ray start --head`` (here on 127.0.0.1,
as a cluster's head runs it), then ``drake-abs experiment ... --address HOST:PORT`` and
``drake-abs sweep ... --address HOST:PORT`` join it and give the numbers of a local run; joining
without the cluster's token is an error that says what to set."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from summary_numbers import assert_same_numbers

pytest.importorskip("ray")

BIN = Path(sys.executable).parent
TIMING = ("seconds", "files", "out")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _environment(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER="0", RAY_USAGE_STATS_ENABLED="0",
               DRAKE_ABS_PROGRESS="0", **extra)  # fmt: skip
    return env


@pytest.fixture(scope="module")
def head():
    """A Ray head on 127.0.0.1 with 2 CPUs (``ray start --head --block``), stopped at the end."""
    port = _free_port()
    proc = subprocess.Popen(
        [str(BIN / "ray"), "start", "--head", f"--port={port}", "--num-cpus=2",
         "--include-dashboard=false", "--disable-usage-stats", "--block"],
        env=_environment(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            assert proc.poll() is None, "ray start --head exited"
            assert time.monotonic() < deadline, "the head did not listen within 120 s"
            time.sleep(0.5)
    yield f"127.0.0.1:{port}", proc.pid
    proc.send_signal(signal.SIGTERM)  # ray start --block stops the processes it started
    try:
        proc.wait(timeout=60)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # anything left of its session
        except ProcessLookupError:
            pass


def _run(args, **env) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "drake-abs"), *args], env=_environment(**env),
                          capture_output=True, text=True, timeout=600)  # fmt: skip


def _same_numbers(a: dict, b: dict) -> None:
    assert_same_numbers(a, b, skip=TIMING, at_least=11)


def test_the_heads_listeners_are_on_the_loopback_interface(head):
    import ipaddress

    import psutil

    session = os.getsid(head[1])
    pids = {p.pid for p in psutil.process_iter() if _sid(p.pid) == session}
    listening = [c for c in psutil.net_connections(kind="inet")
                 if c.status == psutil.CONN_LISTEN and c.pid in pids]  # fmt: skip
    assert listening, "no listener found (the check would pass vacuously)"
    for c in listening:
        address = ipaddress.ip_address(c.laddr.ip)
        address = getattr(address, "ipv4_mapped", None) or address
        assert address.is_loopback, (c.pid, c.laddr)


def _sid(pid: int) -> int | None:
    try:
        return os.getsid(pid)
    except OSError:
        return None


def test_the_same_command_line_joins_a_cluster_with_address(head, tmp_path):
    common = ["experiment", "gradient-variance", "--test-size"]
    local = _run([*common, "--out", str(tmp_path / "local")])
    assert local.returncode == 0, local.stderr[-2000:]
    joined = _run([*common, "--address", head[0], "--out", str(tmp_path / "joined")],
                  RAY_AUTH_MODE="token")  # fmt: skip
    assert joined.returncode == 0, joined.stderr[-2000:]
    assert "Ray worker(s)" in joined.stdout
    _same_numbers(
        json.loads((tmp_path / "local" / "summary.json").read_text()),
        json.loads((tmp_path / "joined" / "summary.json").read_text()),
    )


def test_a_sweep_joins_a_cluster_with_address(head, tmp_path):
    grid = ["sweep", "gradient-variance", "--test-size", "--seeds", "0", "1",
            "--set", "horizons=[10]"]  # fmt: skip
    local = _run([*grid, "--out", str(tmp_path / "local")])
    assert local.returncode == 0, local.stderr[-2000:]
    joined = _run([*grid, "--address", head[0], "--out", str(tmp_path / "joined")],
                  RAY_AUTH_MODE="token")  # fmt: skip
    assert joined.returncode == 0, joined.stderr[-2000:]
    a = json.loads((tmp_path / "local" / "sweep.json").read_text())
    b = json.loads((tmp_path / "joined" / "sweep.json").read_text())
    assert len(b["points"]) == 2
    assert [p["status"] for p in b["points"]] == ["done", "done"]
    for p, q in zip(a["points"], b["points"], strict=True):
        _same_numbers(p["summary"], q["summary"])


def test_joining_without_the_cluster_token_says_what_to_set(head):
    no_token = _run(["experiment", "gradient-variance", "--test-size", "--address", head[0]],
                    RAY_AUTH_MODE="disabled")  # fmt: skip
    assert no_token.returncode != 0
    assert "could not join the Ray cluster" in no_token.stderr
    assert "RAY_AUTH_MODE=token" in no_token.stderr
