"""The web viewer's addresses and the --web options of `auv-swarm view` (the browser test is in integration)."""

from __future__ import annotations

import pytest

from auv_swarm.orchestrator.cli import view
from auv_swarm.recorder import web


def test_page_url_tells_the_page_where_its_proxy_is() -> None:
    assert web.proxy_url("box", 9091) == "rerun+http://box:9091/proxy"
    assert web.page_url("box", 9090, 9091) == "http://box:9090/?url=rerun%2Bhttp%3A%2F%2Fbox%3A9091%2Fproxy"


def test_bad_ports_are_named() -> None:
    with pytest.raises(ValueError, match="--web port"):
        web.check_ports(0, 9091)
    with pytest.raises(ValueError, match="must differ"):
        web.check_ports(9090, 9090)


def test_view_web_usage_errors(tmp_path, capsys) -> None:
    assert view.main(["--web", "70000"]) == 2
    assert "--web port must be in [1, 65535]" in capsys.readouterr().err
    assert view.main([str(tmp_path), "--web"]) == 2
    assert "no recording" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        view.main([])
    assert exc.value.code == 2


def test_a_taken_port_is_refused_before_starting(tmp_path) -> None:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        port = sock.getsockname()[1]
        with pytest.raises(RuntimeError, match=f"port {port} is already in use"):
            web.start(port, port + 1 if port < 65535 else port - 1, tmp_path / "web.log")


def test_bind_addresses_and_the_warning_beyond_loopback() -> None:
    for bad in ("localhost", "0.0.0", "", "example.org"):
        with pytest.raises(ValueError, match="--web-bind must be an IP address"):
            web.check_bind(bad)
    assert web.exposure("127.0.0.1", 9090, 9091) is None and web.exposure("::1", 9090, 9091) is None
    line = web.exposure("0.0.0.0", 9090, 9091)
    assert line.startswith("warning: --web-bind 0.0.0.0:") and "read the live recording" in line and "write" in line
    assert "\n" not in line
    assert (web.local_host("0.0.0.0"), web.local_host("::"), web.local_host("10.1.2.3")) == (
        "127.0.0.1",
        "::1",
        "10.1.2.3",
    )
    assert web.public_host("127.0.0.1") == web.public_host("0.0.0.0") == "localhost"
    assert web.public_host("10.1.2.3") == "10.1.2.3"
    assert web.proxy_url("::1", 9091) == "rerun+http://[::1]:9091/proxy"
    assert web.page_url("::1", 9090, 9091).startswith("http://[::1]:9090/?url=rerun%2Bhttp%3A%2F%2F%5B%3A%3A1%5D")


def test_view_web_refuses_a_bad_bind_before_starting(capsys) -> None:
    assert view.main(["--web", "--web-bind", "my-laptop"]) == 2
    assert capsys.readouterr().err.startswith("error: --web-bind must be an IP address")


def test_the_web_viewer_listens_on_loopback_unless_told_otherwise(tmp_path) -> None:
    from auv_swarm.orchestrator.mission import procs
    from tests.listeners import listeners

    for bind, host in (("127.0.0.1", "127.0.0.1"), ("0.0.0.0", "0.0.0.0")):
        web_port, grpc_port = procs.free_port(), procs.free_port()
        while grpc_port == web_port:
            grpc_port = procs.free_port()
        server = web.start(web_port, grpc_port, tmp_path / "web.log", bind=bind)
        try:
            found = {(x.host, x.port) for x in listeners(server.pid)}
        finally:
            web.stop(server)
        assert found == {(host, web_port), (host, grpc_port)}, found
