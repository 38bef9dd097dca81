"""MQTT alarms (profidrive_cli/monitor/mqtt.py, issue 37) against a real broker: Debian's mosquitto,
started per test on a free port with a config of its own, stopped in teardown. A paho subscriber of the
test's own collects what arrives. Waits poll with generous deadlines; no timing assertions."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time

import pytest

from profidrive_cli import UsageError
from profidrive_cli.monitor.model import MonEvent
from profidrive_cli.monitor.mqtt import MqttAlarms, MqttTarget, parse_url

MOSQUITTO = "/usr/sbin/mosquitto"
DEADLINE_S = 30.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for(cond, what: str, deadline_s: float = DEADLINE_S) -> None:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(0.05)
    pytest.fail(f"not within {deadline_s} s: {what}")


class Broker:
    """One mosquitto on 127.0.0.1:port, config in tmp_path, no persistence; stop() and start() again
    on the same port."""

    def __init__(self, tmp_path, port: int) -> None:
        self.port = port
        self.conf = tmp_path / "mosquitto.conf"
        self.conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
                             "log_dest stderr\n")
        self.log = tmp_path / "mosquitto.log"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)],
                                         stdout=log, stderr=subprocess.STDOUT)

        def up() -> bool:
            assert self.proc is not None
            if self.proc.poll() is not None:
                pytest.fail(f"mosquitto exited: {self.log.read_text()[-2000:]}")
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=1).close()
                return True
            except OSError:
                return False
        wait_for(up, "mosquitto listening")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=DEADLINE_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None


@pytest.fixture
def broker(tmp_path):
    if not os.path.exists(MOSQUITTO):
        if os.environ.get("CI") == "true":
            pytest.fail(f"{MOSQUITTO} is missing under CI (apt-get install mosquitto)")
        pytest.skip("mosquitto not installed")
    b = Broker(tmp_path, _free_port())
    b.start()
    try:
        yield b
    finally:
        b.stop()


class Gate:
    """A TCP relay 127.0.0.1:port -> the broker that the test opens and shuts: shut, the port refuses
    connections and the relayed ones are cut -- the broker gone for the alarms, while the test's
    subscriber (connected to the broker itself) stays subscribed and misses nothing."""

    def __init__(self, target_port: int) -> None:
        self.target = target_port
        self.port = _free_port()
        self._listener: socket.socket | None = None
        self._acceptor: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._socks: list[socket.socket] = []
        self._pumps: list[threading.Thread] = []

    def open(self) -> None:
        ls = socket.socket()
        ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        end = time.monotonic() + DEADLINE_S
        while True:
            try:
                ls.bind(("127.0.0.1", self.port))
                break
            except OSError:
                if time.monotonic() > end:
                    ls.close()
                    raise
                time.sleep(0.1)
        ls.listen(8)
        ls.settimeout(0.1)
        self._listener = ls
        self._stop = threading.Event()
        self._acceptor = threading.Thread(target=self._accept, args=(ls, self._stop), daemon=True)
        self._acceptor.start()

    def _accept(self, ls: socket.socket, stop: threading.Event) -> None:
        while not stop.is_set():
            try:
                c, _ = ls.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                b = socket.create_connection(("127.0.0.1", self.target), timeout=DEADLINE_S)
            except OSError:
                c.close()
                continue
            c.settimeout(None)
            b.settimeout(None)
            with self._lock:
                self._socks += [c, b]
                for src, dst in ((c, b), (b, c)):
                    t = threading.Thread(target=self._pump, args=(src, dst), daemon=True)
                    self._pumps.append(t)
                    t.start()

    @staticmethod
    def _pump(src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := src.recv(65536):
                dst.sendall(data)
        except OSError:
            pass
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def shut(self) -> None:
        self._stop.set()
        if self._acceptor is not None:
            self._acceptor.join(DEADLINE_S)
            self._acceptor = None
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        with self._lock:
            socks, self._socks = self._socks, []
            pumps, self._pumps = self._pumps, []
        for s in socks:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for t in pumps:
            t.join(DEADLINE_S)
        for s in socks:
            s.close()


@pytest.fixture
def gate_factory():
    made: list[Gate] = []

    def make(target_port: int) -> Gate:
        g = Gate(target_port)
        made.append(g)
        return g
    yield make
    for g in made:
        g.shut()


class Subscriber:
    """The test's own paho client, subscribed to PREFIX/#; messages as (topic, payload str, retain)."""

    def __init__(self, port: int, prefix: str = "pdrive") -> None:
        import paho.mqtt.client as mqtt
        from paho.mqtt.enums import CallbackAPIVersion
        self.messages: list[tuple[str, str, bool]] = []
        self.lock = threading.Lock()
        self.subscribed = threading.Event()
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=f"test-sub-{id(self):x}")
        self.prefix = prefix

        def on_connect(client, userdata, flags, rc, props=None):
            client.subscribe(f"{prefix}/#", qos=1)

        def on_subscribe(client, userdata, mid, rcs, props=None):
            self.subscribed.set()

        def on_message(client, userdata, msg):
            with self.lock:
                self.messages.append((msg.topic, msg.payload.decode(), bool(msg.retain)))

        self.client.on_connect = on_connect
        self.client.on_subscribe = on_subscribe
        self.client.on_message = on_message
        self.client.reconnect_delay_set(1, 2)
        self.client.connect_async("127.0.0.1", port, keepalive=10)
        self.client.loop_start()
        assert self.subscribed.wait(DEADLINE_S), "subscriber not subscribed"

    def on(self, topic: str) -> list[tuple[str, bool]]:
        with self.lock:
            return [(p, r) for t, p, r in self.messages if t == topic]

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


@pytest.fixture
def sub_factory():
    subs: list[Subscriber] = []

    def make(port: int, prefix: str = "pdrive") -> Subscriber:
        s = Subscriber(port, prefix)
        subs.append(s)
        return s
    yield make
    for s in subs:
        s.close()


@pytest.fixture
def alarms_factory():
    made: list[MqttAlarms] = []

    def make(url: str, **kw) -> tuple[MqttAlarms, list[str]]:
        lines: list[str] = []
        a = MqttAlarms(url, log=lines.append, **kw)
        made.append(a)
        return a, lines
    yield make
    for a in made:
        a.close(timeout=5.0)


EV = MonEvent(t=1764900000.25, kind="nr", station=5, text="station 5 did not answer",
              cause="cable or power at 5", evidence=("3 retries",), repeats=2, capture="c1.pcap")


# -- parse_url ------------------------------------------------------------------------------------

def test_parse_url_forms() -> None:
    assert parse_url("mqtt://broker") == MqttTarget("broker", 1883, "pdrive")
    assert parse_url("mqtt://broker:1884/plant/line3/") == MqttTarget("broker", 1884, "plant/line3")
    assert parse_url("mqtt://u:p%40ss@10.0.0.2/x") == MqttTarget("10.0.0.2", 1883, "x",
                                                                   username="u", password="p@ss")
    assert parse_url("mqtt://u@h") == MqttTarget("h", 1883, "pdrive", username="u")
    assert parse_url("mqtts://h") == MqttTarget("h", 8883, "pdrive", tls=True)
    assert parse_url("MQTT://[::1]:2000") == MqttTarget("::1", 2000, "pdrive")


@pytest.mark.parametrize("url, says", [
    ("http://h", "scheme"),
    ("broker:1883", "scheme"),
    ("mqtt://", "no host"),
    ("mqtt://h:0", "port"),
    ("mqtt://h:99999", "port"),
    ("mqtt://h:abc", "port"),
    ("mqtt://h/a/+/b", "wildcard"),
    ("mqtt://h/a#b", "fragment"),
    ("mqtt://h?x=1", "query"),
    ("mqtt://:pw@h", "password without a user"),
])
def test_parse_url_errors(url: str, says: str) -> None:
    with pytest.raises(UsageError) as err:
        parse_url(url)
    msg = str(err.value)
    assert "\n" not in msg and "--mqtt" in msg and says in msg


def test_bad_url_is_usage_error_at_construction() -> None:
    with pytest.raises(UsageError, match="--mqtt"):
        MqttAlarms("mqtt://h:nope")


def test_no_paho_at_import() -> None:
    code = ("import sys, profidrive_cli.monitor.mqtt\n"
            "print(sorted(m for m in sys.modules if m.startswith('paho')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_missing_extra_is_usage_error() -> None:
    # paho made unimportable in a child: the constructor says which extra to install
    code = ("import sys; sys.modules['paho'] = None\n"
            "from profidrive_cli import UsageError\n"
            "from profidrive_cli.monitor.mqtt import MqttAlarms\n"
            "try:\n    MqttAlarms('mqtt://h')\nexcept UsageError as e:\n    print('USAGE', e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "USAGE --mqtt needs the mqtt extra: pip install 'profidrive-cli[mqtt]'"


def test_old_paho_is_usage_error() -> None:
    # paho-mqtt before 2.2 has no drop_out_messages: the constructor says to upgrade
    code = ("import paho.mqtt.client as c; del c.Client.drop_out_messages\n"
            "from profidrive_cli import UsageError\n"
            "from profidrive_cli.monitor.mqtt import MqttAlarms\n"
            "try:\n    MqttAlarms('mqtt://h')\nexcept UsageError as e:\n    print('USAGE', e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "USAGE --mqtt needs paho-mqtt 2.2 or newer: pip install -U 'profidrive-cli[mqtt]'"


# -- against the broker -----------------------------------------------------------------------------

def test_status_and_event(broker, sub_factory, alarms_factory) -> None:
    sub = sub_factory(broker.port)
    a, lines = alarms_factory(f"mqtt://127.0.0.1:{broker.port}")
    a.start()
    wait_for(lambda: a.connected, "connected")
    wait_for(lambda: ("online", True) in sub.on("pdrive/status")
             or ("online", False) in sub.on("pdrive/status"), "status online")
    # retained: a subscriber that comes later gets it with the retain flag
    late = sub_factory(broker.port)
    wait_for(lambda: ("online", True) in late.on("pdrive/status"), "status online retained")

    a.event(EV)
    a.event(MonEvent(t=1764900001.0, kind="fcs", station=None, text="bad frame check"))
    wait_for(lambda: sub.on("pdrive/event/nr/5") and sub.on("pdrive/event/fcs/bus"), "both events")
    payload, retained = sub.on("pdrive/event/nr/5")[0]
    assert not retained
    assert json.loads(payload) == {
        "t": 1764900000.25, "kind": "nr", "station": 5, "text": "station 5 did not answer",
        "cause": "cable or power at 5", "evidence": ["3 retries"], "repeats": 2, "capture": "c1.pcap",
        # 1764900000 s after the epoch: 20427 days (1970-01-01 + 20427 d = 2025-12-05) + 7200 s
        "time": "2025-12-05T02:00:00.250+00:00"}
    assert json.loads(sub.on("pdrive/event/fcs/bus")[0][0])["station"] is None
    wait_for(lambda: a.published == 2, "two acknowledged")
    assert a.dropped == 0
    assert any("connected" in line for line in lines)


def test_prefix_from_url(broker, sub_factory, alarms_factory) -> None:
    sub = sub_factory(broker.port, prefix="plant/line3")
    a, _ = alarms_factory(f"mqtt://127.0.0.1:{broker.port}/plant/line3")
    a.start()
    a.event(EV)
    wait_for(lambda: sub.on("plant/line3/event/nr/5"), "event under the prefix")
    wait_for(lambda: sub.on("plant/line3/status"), "status under the prefix")


def test_station_state_retained_on_change(broker, sub_factory, alarms_factory) -> None:
    sub = sub_factory(broker.port)
    a, _ = alarms_factory(f"mqtt://127.0.0.1:{broker.port}")
    a.start()
    wait_for(lambda: a.connected, "connected")
    topic = "pdrive/station/7/state"
    a.station_state(7, "data exchange", "operation", False, t=100.0)
    a.station_state(7, "data exchange", "operation", False, t=101.0)   # unchanged: nothing
    a.station_state(7, "data exchange", "fault", True, t=102.0)
    a.station_state(7, "data exchange", "fault", True, t=103.0)        # unchanged: nothing
    a.event(EV)   # after the states in the same order through one client: a marker
    wait_for(lambda: sub.on("pdrive/event/nr/5"), "marker event")
    wait_for(lambda: a.published == 3, "two states and the event acknowledged")
    got = [json.loads(p) for p, _ in sub.on(topic)]
    assert got == [{"state": "data exchange", "drive_state": "operation", "fault": False, "t": 100.0},
                   {"state": "data exchange", "drive_state": "fault", "fault": True, "t": 102.0}]
    late = sub_factory(broker.port)
    wait_for(lambda: late.on(topic), "retained state for a late subscriber")
    payload, retained = late.on(topic)[0]
    assert retained and json.loads(payload)["drive_state"] == "fault"


def _seen(sub: Subscriber, topics: set[str]) -> list[tuple[str, str]]:
    """What the subscriber got on `topics`, in the order it came: (topic, payload)."""
    with sub.lock:
        return [(t, p) for t, p, _ in sub.messages if t in topics]


def test_broker_away_and_back(broker, gate_factory, sub_factory, alarms_factory) -> None:
    # the alarms reach the broker through the gate; the subscriber is on the broker itself throughout
    gate = gate_factory(broker.port)
    gate.open()
    sub = sub_factory(broker.port)
    a, lines = alarms_factory(f"mqtt://127.0.0.1:{gate.port}")
    a.start()
    wait_for(lambda: a.connected, "connected")
    a.station_state(7, "data exchange", "operation", False, t=100.0)
    wait_for(lambda: a.published == 1, "the first state acknowledged")

    gate.shut()
    wait_for(lambda: not a.connected, "the loss noticed")
    # the broker sends the monitor's last will for the cut connection
    wait_for(lambda: sub.on("pdrive/status")[-1:] == [("offline", False)], "the will: offline")
    a.event(MonEvent(t=1000.0, kind="lost", station=10, text="station 10 lost"))
    a.event(MonEvent(t=1001.0, kind="lost", station=11, text="station 11 lost"))
    a.station_state(7, "data exchange", "fault", True, t=1001.5)
    for i in (12, 13, 14):
        a.event(MonEvent(t=1000.0 + i - 10, kind="lost", station=i, text=f"station {i} lost"))
    # several reconnect attempts fail meanwhile (back-off from 1 s): let a few pass
    time.sleep(3.0)
    assert not a.connected and a.published == 1
    assert len([line for line in lines if "lost" in line]) == 1, lines
    assert "Traceback" not in "".join(lines)

    gate.open()
    wait_for(lambda: a.connected, "reconnected", deadline_s=60.0)
    # five events and one state change queued while away: all acknowledged, none dropped
    wait_for(lambda: a.published == 1 + 6, "the queued messages acknowledged")
    assert a.dropped == 0
    state = "pdrive/station/7/state"
    topics = {state} | {f"pdrive/event/lost/{i}" for i in range(10, 15)}
    wait_for(lambda: len(_seen(sub, topics)) == 7, "all seven on the subscriber")
    # in the order they were given (the first state from before the loss, then the queue's order)
    assert [t for t, _ in _seen(sub, topics)] == [
        state, "pdrive/event/lost/10", "pdrive/event/lost/11", state,
        "pdrive/event/lost/12", "pdrive/event/lost/13", "pdrive/event/lost/14"]
    assert json.loads(_seen(sub, {state})[-1][1]) == {
        "state": "data exchange", "drive_state": "fault", "fault": True, "t": 1001.5}
    wait_for(lambda: sub.on("pdrive/status")[-1:] == [("online", False)], "online again")
    assert len([line for line in lines if "back" in line]) == 1, lines
    assert len([line for line in lines if "lost" in line]) == 1, lines


def test_queue_bounded_while_away(broker, gate_factory, sub_factory, alarms_factory) -> None:
    gate = gate_factory(broker.port)
    gate.open()
    sub = sub_factory(broker.port)
    a, lines = alarms_factory(f"mqtt://127.0.0.1:{gate.port}", max_queue=3)
    a.start()
    wait_for(lambda: a.connected, "connected")
    gate.shut()
    wait_for(lambda: not a.connected, "the loss noticed")
    for i in range(5):
        a.event(MonEvent(t=float(i), kind="rr", station=i, text=f"e{i}"))
    # 5 into a queue of 3: the two oldest dropped, counted, said once
    assert a.dropped == 2
    assert len([line for line in lines if "queue full" in line]) == 1, lines
    gate.open()
    wait_for(lambda: a.published == 3, "the three kept acknowledged", deadline_s=60.0)
    topics = {f"pdrive/event/rr/{i}" for i in range(5)}
    wait_for(lambda: len(_seen(sub, topics)) == 3, "three on the subscriber")
    assert [t for t, _ in _seen(sub, topics)] == [f"pdrive/event/rr/{i}" for i in (2, 3, 4)]


def test_state_dropped_from_queue_is_said_again(broker, gate_factory, sub_factory,
                                                alarms_factory) -> None:
    # a station's latest state pushed out of the full queue: its retained topic must still end at it
    gate = gate_factory(broker.port)
    gate.open()
    sub = sub_factory(broker.port)
    a, _ = alarms_factory(f"mqtt://127.0.0.1:{gate.port}", max_queue=2)
    a.start()
    wait_for(lambda: a.connected, "connected")
    gate.shut()
    wait_for(lambda: not a.connected, "the loss noticed")
    a.station_state(7, "data exchange", "fault", True, t=50.0)
    for i in range(3):
        a.event(MonEvent(t=60.0 + i, kind="rr", station=i, text=f"e{i}"))
    assert a.dropped == 2          # the state and event 0
    gate.open()
    state = "pdrive/station/7/state"
    wait_for(lambda: _seen(sub, {state}), "the state said again", deadline_s=60.0)
    assert json.loads(_seen(sub, {state})[-1][1]) == {
        "state": "data exchange", "drive_state": "fault", "fault": True, "t": 50.0}
    wait_for(lambda: a.published == 3, "the state and the two events kept acknowledged")
    late = sub_factory(broker.port)
    wait_for(lambda: late.on(state), "the retained state for a late subscriber")
    assert json.loads(late.on(state)[0][0])["drive_state"] == "fault" and late.on(state)[0][1]


def test_states_said_again_after_broker_restart(broker, sub_factory, alarms_factory) -> None:
    # a broker without persistence forgets the retained states when it restarts: said again
    a, _ = alarms_factory(f"mqtt://127.0.0.1:{broker.port}")
    a.start()
    wait_for(lambda: a.connected, "connected")
    a.station_state(3, "data exchange", "operation", False, t=10.0)
    a.station_state(9, "no answer", None, None, t=11.0)
    wait_for(lambda: a.published == 2, "both states acknowledged")
    broker.stop()
    wait_for(lambda: not a.connected, "the loss noticed")
    broker.start()
    wait_for(lambda: a.connected, "reconnected", deadline_s=60.0)
    # retained: the subscriber gets them whenever it comes
    sub = sub_factory(broker.port)
    wait_for(lambda: sub.on("pdrive/station/3/state") and sub.on("pdrive/station/9/state"),
             "both states again")
    assert json.loads(sub.on("pdrive/station/3/state")[-1][0]) == {
        "state": "data exchange", "drive_state": "operation", "fault": False, "t": 10.0}
    assert json.loads(sub.on("pdrive/station/9/state")[-1][0]) == {
        "state": "no answer", "drive_state": None, "fault": None, "t": 11.0}
    wait_for(lambda: ("online", True) in sub.on("pdrive/status")
             or ("online", False) in sub.on("pdrive/status"), "online again")


def test_not_there_at_start(broker, gate_factory, sub_factory, alarms_factory) -> None:
    gate = gate_factory(broker.port)   # not open yet: nothing listens on its port
    sub = sub_factory(broker.port)
    a, lines = alarms_factory(f"mqtt://127.0.0.1:{gate.port}")
    a.start()   # no broker: not an error
    a.event(EV)
    wait_for(lambda: any("not reachable" in line for line in lines), "not reachable said")
    time.sleep(2.5)   # a few retries pass: still one line
    assert len([line for line in lines if "not reachable" in line]) == 1, lines
    gate.open()
    wait_for(lambda: sub.on("pdrive/event/nr/5"), "the queued event", deadline_s=60.0)
    wait_for(lambda: a.published == 1, "acknowledged")
    assert any("back" in line for line in lines), lines


def test_queue_overflow_drops_oldest(broker, sub_factory, alarms_factory) -> None:
    a, lines = alarms_factory(f"mqtt://127.0.0.1:{broker.port}", max_queue=3)
    # not started: nothing leaves, the queue fills
    for i in range(5):
        a.event(MonEvent(t=float(i), kind="rr", station=i, text=f"e{i}"))
    assert a.dropped == 2
    assert len([line for line in lines if "queue full" in line]) == 1
    sub = sub_factory(broker.port)
    a.start()
    wait_for(lambda: a.published == 3, "the three kept")
    wait_for(lambda: all(sub.on(f"pdrive/event/rr/{i}") for i in (2, 3, 4)), "events 2..4")
    assert not sub.on("pdrive/event/rr/0") and not sub.on("pdrive/event/rr/1")


def test_close_says_offline_within_bound(broker, sub_factory, alarms_factory) -> None:
    sub = sub_factory(broker.port)
    a, _ = alarms_factory(f"mqtt://127.0.0.1:{broker.port}")
    a.start()
    wait_for(lambda: a.connected, "connected")
    wait_for(lambda: sub.on("pdrive/status"), "online")
    t0 = time.monotonic()
    a.close(timeout=2.0)
    # the bound: the timeout plus the small fixed slack of the joins, generous for a loaded machine
    assert time.monotonic() - t0 < 2.0 + 10.0
    wait_for(lambda: sub.on("pdrive/status")[-1][0] == "offline", "offline")
    late = sub_factory(broker.port)
    wait_for(lambda: late.on("pdrive/status") == [("offline", True)], "offline retained")
    a.event(EV)   # after close: ignored, no exception
    assert not a.connected


def test_close_without_broker_is_bounded(tmp_path, alarms_factory) -> None:
    a, _ = alarms_factory(f"mqtt://127.0.0.1:{_free_port()}")
    a.start()
    a.event(EV)
    t0 = time.monotonic()
    a.close(timeout=1.0)
    assert time.monotonic() - t0 < 1.0 + 10.0
