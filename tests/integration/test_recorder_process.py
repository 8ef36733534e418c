"""The recorder process on a real router: it records what the world and the AUVs publish, survives malformed
telemetry, leaves a readable recording when killed with SIGKILL, exits by itself after the world's end event,
and streams to a live viewer given by --rerun-url."""

from __future__ import annotations

import math
import os
import socket
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from auv_swarm.contract import wire
from auv_swarm.contract.config import load_scenario
from auv_swarm.orchestrator.mission import procs
from tests.unit.test_recorder import read_rrd

from .conftest import until

pytestmark = [pytest.mark.integration, pytest.mark.filterwarnings("ignore:RRD file has no footer")]

SCENARIO = "paper-3.2-challenging"
N = load_scenario(SCENARIO).agents.count


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def _truth(k: int) -> wire.Truth:
    t = 2.0 * k
    agents = {a: (100.0 * a + 1.5 * t, -50.0 * a + 0.25 * t, 0.1 * a) for a in range(N)}
    return wire.Truth(
        t_s=t, source="world", tick=k, target=(-450.0 + 0.3 * t, 105.0, 0.3, 0.0), agents=agents, alive=tuple(range(N))
    )


def _telemetry(k: int, a: int) -> wire.Telemetry:
    tr = _truth(k)
    return wire.Telemetry(
        t_s=tr.t_s,
        source=f"auv/{a}",
        tick=k,
        auv=a,
        estimate_ok=True,
        estimate_reason="",
        xi=(tr.target[0] + 3.0 + a, tr.target[1] - 4.0, 0.3, 0.0),
        P=(9.0, 0, 0, 0, 0, 9.0, 0, 0, 0, 0, 0.01, 0, 0, 0, 0, 0.01),
        plan=((0.0, 2.0),) * 5,
        waypoints=tuple((tr.agents[a][0] + 260.0 * h, tr.agents[a][1]) for h in range(1, 6)),
        cost=1.0,
        terms={"geometry": 0.7, "distance": 0.2, "connectivity": 0.1},
        plan_wall_ms=2.5,
        n_measurements=k,
        planned=True,
        fiedler=3.0,
        nav=tr.agents[a],
    )


def _has_rows(path: Path, times: set[int], entities: tuple[str, ...] = ("world/target/truth",)) -> bool:
    """True once the recording at ``path`` holds rows at every sim time of ``times`` (ns) for each of ``entities``."""
    if not path.exists():
        return False
    try:
        data = read_rrd(path)
    except Exception:
        return False
    return all(times <= set(data.get(e, {})) for e in entities)


def _start_recorder(spawner, router, out: Path, *extra: str):
    argv = procs.python_argv(
        "auv_swarm",
        "recorder",
        "--scenario",
        SCENARIO,
        "--router",
        router.endpoint,
        "--out",
        str(out),
        "--flush-s",
        "0.2",
        *extra,
    )
    proc = spawner(argv, "recorder")
    procs.wait_for_line(proc, r"recorder ready", timeout=30.0)
    return proc


def _publish_mission(connect, router, rrd: Path, ticks: int, malformed: bool = False) -> None:
    """Publish truth and telemetry for ``ticks`` ticks; the first tick is repeated until the recording holds it."""
    world = connect(router.endpoint, "world")
    auvs = [connect(router.endpoint, f"auv{a}") for a in range(N)]

    def publish_tick(k: int) -> None:
        world.publish(wire.truth(), wire.encode(_truth(k)))
        for a, bus in enumerate(auvs):
            bus.publish(wire.telemetry(a), wire.encode(_telemetry(k, a)))

    everyone = ("world/target/truth", *(f"plots/tracking_error/auv{a}" for a in range(N)))
    assert until(lambda: publish_tick(0) or _has_rows(rrd, {0}, everyone), timeout=20.0, poll_s=0.3), "no route"
    if malformed:
        auvs[1].publish(wire.telemetry(1), b"\x93\x01 not msgpack")
        auvs[1].publish(wire.telemetry(1), wire.encode(wire.Clock(t_s=0.0, source="auv/1", tick=0, alive=(1,))))
    for k in range(1, ticks):
        publish_tick(k)
    world.publish(
        wire.world_events(), wire.encode(wire.WorldEvent(t_s=0.0, source="world", kind="kill", auv=2, text="x"))
    )


def _check_recording(rrd: Path, ticks: int) -> None:
    data = read_rrd(rrd)
    for k in range(ticks):
        tr = _truth(k)
        assert data["world/target/truth"][_ns(tr.t_s)]["Points2D:positions"] == [[pytest.approx(tr.target[0]), 105.0]]
        for a in range(N):
            got = data[f"world/auv/{a}/truth"][_ns(tr.t_s)]["Points2D:positions"]
            assert got == [pytest.approx(tr.agents[a][:2], rel=1e-6)]
            err = data[f"plots/tracking_error/auv{a}"][_ns(tr.t_s)]["Scalars:scalars"][0]
            assert err == pytest.approx(math.hypot(3.0 + a, 4.0))
    for a in range(N):
        for tail in ("estimate", "estimate/covariance", "plan", "bearing", "trail"):
            assert f"world/auv/{a}/{tail}" in data


def test_recording_survives_kill_9_and_malformed_telemetry(start_router, spawner, connect, tmp_path: Path) -> None:
    router = start_router(agents=N)
    rrd = tmp_path / "out" / "recording.rrd"
    recorder = _start_recorder(spawner, router, tmp_path / "out")
    ticks = 20
    _publish_mission(connect, router, rrd, ticks, malformed=True)
    expected = {_ns(2.0 * k) for k in range(ticks)}
    everyone = ("world/target/truth", *(f"plots/tracking_error/auv{a}" for a in range(N)))
    assert until(lambda: _has_rows(rrd, expected, everyone), timeout=20.0, poll_s=0.3)
    assert recorder.poll() is None, "malformed telemetry must not stop the recorder"
    procs.kill(recorder)
    assert recorder.returncode == -9
    _check_recording(rrd, ticks)
    assert "events" in read_rrd(rrd)
    log = procs.read_log(recorder)
    assert "recorder: dropped a message on auvswarm/auv/1/telemetry" in log
    assert len(list(RrdReader(rrd).stream())) > 0


def test_recorder_exits_after_the_world_end_event(start_router, spawner, connect, tmp_path: Path) -> None:
    router = start_router(agents=N)
    rrd = tmp_path / "out" / "recording.rrd"
    recorder = _start_recorder(spawner, router, tmp_path / "out")
    _publish_mission(connect, router, rrd, 5)
    world = connect(router.endpoint, "world")
    end = wire.WorldEvent(t_s=10.0, source="world", kind="end", auv=-1, text="mission complete")
    assert until(lambda: world.publish(wire.world_events(), wire.encode(end)) or recorder.poll() is not None, 15.0, 0.5)
    assert recorder.returncode == 0, procs.read_log(recorder)
    assert "recorder stopped" in procs.read_log(recorder)
    _check_recording(rrd, 5)
    texts = [t for row in read_rrd(rrd)["events"].values() for t in row["TextLog:text"]]
    assert any(t.startswith("end: mission complete") for t in texts)
    store = RrdReader(rrd).store()
    assert store is not None, "a cleanly closed recording has its footer"


def _vulkan_driver_installed() -> bool:
    """True if a Vulkan ICD is registered: the headless viewer cannot get a render context without one."""
    if os.environ.get("VK_ICD_FILENAMES") or os.environ.get("VK_DRIVER_FILES"):
        return True
    dirs = ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d", "/usr/local/share/vulkan/icd.d")
    return any(any(Path(d).glob("*.json")) for d in dirs)


def test_recorder_streams_to_a_live_viewer_at_rerun_url(start_router, spawner, connect, tmp_path: Path) -> None:
    from rerun.experimental import ViewerClient

    if not _vulkan_driver_installed():
        pytest.skip("the headless rerun viewer needs a Vulkan driver (Debian: apt-get install mesa-vulkan-drivers)")

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    viewer = ViewerClient.spawn(headless=True, port=port, hide_welcome_screen=True, detach_process=False)
    try:
        router = start_router(agents=N)
        rrd = tmp_path / "out" / "recording.rrd"
        recorder = _start_recorder(
            spawner, router, tmp_path / "out", "--rerun-url", f"rerun+http://127.0.0.1:{port}/proxy"
        )
        _publish_mission(connect, router, rrd, 10)

        def viewer_has_tick_9() -> bool:
            ends = [tl.end for rec in viewer.get_state().recordings for tl in rec.timelines if tl.name == "sim_time"]
            return bool(ends) and max(ends) >= _ns(18.0)

        assert until(viewer_has_tick_9, timeout=20.0, poll_s=0.3), "the live viewer never got the data"
        procs.stop(recorder, timeout=10.0)
        assert recorder.returncode == 0, procs.read_log(recorder)
        _check_recording(rrd, 10)
    finally:
        viewer.quit()
