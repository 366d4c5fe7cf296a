"""Dask scheduler addresses: parsed, connected with a timeout, one line on any failure (127.0.0.1 only)."""

from __future__ import annotations

import socket
import threading

import pytest

import multilat.parallel as par
from multilat.errors import MultilatError


@pytest.mark.parametrize("address", ["", "not a url", "http://127.0.0.1:8787", "tcp://127.0.0.1",
                                     "tcp://127.0.0.1:0", "tcp://127.0.0.1:70000", "tcp://:8786",
                                     "tcp://a b:1", "udp://127.0.0.1:8786", "tcp://127.0.0.1:8786/x/y",
                                     "127.0.0.1:99999999999999999999"])
def test_malformed_address(ws, address):
    ws.fails(["propagate", "small-volume", "--trials", "100", "--scheduler", address], "--scheduler")


@pytest.fixture
def fast_timeouts(monkeypatch):
    monkeypatch.setattr(par, "CONNECT_TIMEOUT_S", 0.5)
    monkeypatch.setattr(par, "CLIENT_TIMEOUT_S", 2.0)


def _server(behaviour):
    """A TCP server on 127.0.0.1 that accepts connections and then ``behaviour(conn)``."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    conns = []

    def loop():
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            conns.append(c)
            behaviour(c)

    threading.Thread(target=loop, daemon=True).start()
    return srv, conns


def test_silent_listener_is_not_a_scheduler(ws, fast_timeouts):
    srv, conns = _server(lambda c: None)            # like an HTTP dashboard: waits for a request
    try:
        port = srv.getsockname()[1]
        line = ws.fails(["propagate", "small-volume", "--trials", "100", "--scheduler",
                         f"tcp://127.0.0.1:{port}"], "--scheduler", "not a Dask scheduler")
        assert "8786" in line
    finally:
        srv.close()
        for c in conns:
            c.close()


def test_listener_closing_at_once(ws, fast_timeouts):
    srv, _ = _server(lambda c: c.close())
    try:
        port = srv.getsockname()[1]
        ws.fails(["propagate", "small-volume", "--trials", "100", "--scheduler", f"127.0.0.1:{port}"],
                 "--scheduler")
    finally:
        srv.close()


def test_nothing_listening(ws, fast_timeouts):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()                                        # a port nobody listens on
    ws.fails(["propagate", "small-volume", "--trials", "100", "--scheduler", f"tcp://127.0.0.1:{port}"],
             "--scheduler", "cannot connect")


def test_garbage_speaker_gets_one_line(ws, fast_timeouts):
    srv, conns = _server(lambda c: c.sendall(b"SSH-2.0-OpenSSH_9.6\r\n"))
    try:
        port = srv.getsockname()[1]
        ws.fails(["propagate", "small-volume", "--trials", "100", "--scheduler", f"tcp://127.0.0.1:{port}"],
                 "--scheduler")
    finally:
        srv.close()
        for c in conns:
            c.close()


def test_parse_accepts_the_usual_forms():
    assert par.parse_scheduler_address("tcp://127.0.0.1:8786") == ("tcp", "127.0.0.1", 8786)
    assert par.parse_scheduler_address("localhost:8786") == ("tcp", "localhost", 8786)
    assert par.parse_scheduler_address("tls://[::1]:8786") == ("tls", "::1", 8786)
    with pytest.raises(MultilatError, match="--scheduler"):
        par.parse_scheduler_address("http://localhost:8787")
