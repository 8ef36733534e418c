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
