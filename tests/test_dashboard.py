"""The live dashboard without a browser (issue 19 item 2): access control, the options'
checks, the live state's envelopes and spectrum, the operator's requests reaching the
supervisor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.control.arbitration import Supervisor
from millsense.core.errors import ConfigError
from millsense.dashboard.live import SPECTRUM_SAMPLES, LiveState
from millsense.dashboard.server import DashboardOptions, create_app, is_loopback
from millsense.streaming.block import Chunk, Event, EventKind, Severity

# starlette's TestClient on httpx (its successor package is not needed for these tests)
pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx`")
FS = 10000.0
TOKEN = "t" * 32


def _client(state: LiveState) -> object:
    pytest.importorskip("fastapi")
    from fastapi.testclient import TestClient

    return TestClient(create_app(state, TOKEN))


def test_requests_without_the_token_are_refused() -> None:
    """Every route: no token or a wrong one → 401 (the websocket handshake is closed with
    1008, an HTTP 403); the right one as query or bearer header → 200."""
    from starlette.websockets import WebSocketDisconnect

    c = _client(LiveState())
    for path in ("/", "/api/state", "/plotly.min.js"):
        assert c.get(path).status_code == 401  # type: ignore[attr-defined]
        assert c.get(path + "?token=" + "x" * 32).status_code == 401  # type: ignore[attr-defined]
        assert c.get(path + "?token=" + TOKEN).status_code == 200  # type: ignore[attr-defined]
    ok = c.get("/api/state", headers={"Authorization": f"Bearer {TOKEN}"})  # type: ignore[attr-defined]
    assert ok.status_code == 200 and ok.json()["chunks"] == 0
    assert c.post("/api/control?on=false").status_code == 401  # type: ignore[attr-defined]
    assert c.post("/api/ack/0").status_code == 401  # type: ignore[attr-defined]
    with pytest.raises(WebSocketDisconnect) as exc, c.websocket_connect("/ws"):  # type: ignore[attr-defined]
        pass
    assert exc.value.code == 1008
    with c.websocket_connect("/ws?token=" + TOKEN) as ws:  # type: ignore[attr-defined]
        assert ws.receive_json()["chunks"] == 0


def test_serving_beyond_localhost_needs_the_flag_and_tls(tmp_path: Path) -> None:
    cert, key = tmp_path / "c.pem", tmp_path / "k.pem"
    cert.write_text("x")
    key.write_text("x")
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.10")
    with pytest.raises(ConfigError, match="--dashboard-allow-remote"):
        DashboardOptions(host="0.0.0.0")
    with pytest.raises(ConfigError, match="needs TLS"):
        DashboardOptions(host="0.0.0.0", allow_remote=True)
    with pytest.raises(ConfigError, match="give both"):
        DashboardOptions(tls_cert=cert)
    with pytest.raises(ConfigError, match="no such file"):
        DashboardOptions(tls_cert=tmp_path / "none.pem", tls_key=key)
    o = DashboardOptions(host="0.0.0.0", allow_remote=True, tls_cert=cert, tls_key=key)
    assert o.scheme == "https"
    assert DashboardOptions().host == "127.0.0.1"
    a, b = DashboardOptions().token, DashboardOptions().token
    assert len(a) >= 32 and a != b  # 24 random bytes, url-safe base64


def test_live_state_envelopes_spectrum_and_alarms() -> None:
    """Chunks of a 100 Hz tone (amplitude 2) with one 50 N·m spike: the kept maximum of the
    spike's chunk is the spike (no peak dropped), the rolling spectrum peaks at 100 Hz ± one bin
    with amplitude 2 ± 2 % (Hann window, amplitude scaling), the alarm is listed."""
    sup = Supervisor([], fault_channel=None, in_cut_channel=None)
    st = LiveState(sup)
    n = 20000
    t = np.arange(n) / FS
    tq = 2.0 * np.sin(2 * np.pi * 100.0 * t)
    tq[12345] = 50.0
    for a in range(0, n, 100):
        ch = Chunk(a, FS, 0.0, {"est/spindle/spindle/load": tq[a : a + 100],
                                "spindle/speed": np.full(100, 1000 * np.pi / 30)})  # fmt: skip
        ev = [Event(1.5, EventKind.ALARM, "breakage", "tool breakage", name="breakage",
                    severity=Severity.CRITICAL)] if a == 15000 else []  # fmt: skip
        st.observe(ch, {}, ev)
    snap = st.snapshot()
    hi = snap["plots"]["torque"]["traces"][0]["hi"]
    assert max(hi) == 50.0 and len(hi) == 200
    f, amp = np.array(snap["spectrum"]["f"]), np.array(snap["spectrum"]["amp"])
    assert abs(f[np.argmax(amp)] - 100.0) <= FS / SPECTRUM_SAMPLES
    assert amp.max() == pytest.approx(2.0, rel=0.02)
    assert snap["spectrum"]["tooth_hz"] == pytest.approx(2 * 1000 / 60)
    assert [a["name"] for a in snap["alarms"]] == ["breakage"]
    assert st.acknowledge(0) and not st.acknowledge(5)
    st.set_control(False)
    # the requests reach the supervisor: taken at its next control period
    out = sup.process(Chunk(n, FS, 0.0, {}))
    assert out.events == []  # an empty chunk decides nothing
    out = sup.process(Chunk(n, FS, 0.0, {"x": np.zeros(100)}))
    assert {e.name for e in out.events} == {"alarm_acknowledged", "control_off"}
    snap = st.snapshot()
    assert snap["status"]["control"] is False
    assert snap["status"]["spindle_rpm"] == pytest.approx(1000.0)


@pytest.mark.parametrize(
    ("unit", "title"),
    [("W", "spindle power [W]"), ("N*m", "cutting torque [N·m]"), ("", "regulated")],
)
def test_live_regulated_plot_is_titled_with_its_quantity_and_unit(unit: str, title: str) -> None:
    """The dashboard's regulated plot names the quantity and its unit, as ``run --plot`` and
    the report do (found by the qa4 helper: 'regulated quantity', no unit, beside 'spindle
    torque [N·m]'); its trace says per control interval (it said per rev., which it is only
    where a revolution lasts the 10 ms interval: 6000 rev/min). One 100-sample chunk of a
    900 W regulated power: the trace holds 900."""
    st = LiveState(regulated_unit=unit)
    ch = Chunk(0, FS, 0.0, {"spindle/speed": np.full(100, 628.3)})
    st.observe(ch, {"adaptive_feed/peak": np.full(100, 900.0)}, [])
    plot = st.snapshot()["plots"]["regulated"]
    assert plot["title"] == title
    (trace,) = plot["traces"]
    assert trace["name"] == "regulated (per control interval)" and trace["hi"] == [900.0]
