"""MQTT alarms of `pdrive monitor --mqtt URL` (issue 37): the monitor's events and its stations' states
published to a broker through paho-mqtt 2.2 or newer (extra `mqtt`, imported only when an MqttAlarms
is made).

URL: `mqtt://[user[:password]@]host[:port][/topic/prefix]` (port 1883, prefix "pdrive"), or
`mqtts://...` (TLS with the system's CAs, port 8883).

Topic layout (PREFIX: the URL's path, "pdrive" when none):

    PREFIX/status                 "online" / "offline", retained, QoS 1. "online" at every (re)connect,
                                  "offline" at close(); also the last will, so the broker says
                                  "offline" for a monitor that died or lost its network.
    PREFIX/event/KIND/STATION     one message per MonEvent, QoS 1, not retained. KIND: MonEvent.kind
                                  (model.EVENT_KINDS); STATION: the station number, or "bus" for an
                                  event of no station. Payload: JSON, MonEvent.as_dict() plus "time"
                                  (ISO 8601, UTC, of the event's t).
    PREFIX/station/N/state        retained JSON {"state", "drive_state", "fault", "t"}, QoS 1, one
                                  message per change of state / drive_state / fault (none for a
                                  repeat), and the latest again after every reconnect (for a broker
                                  that lost its retained ones).

Promises: nothing here blocks the monitor or raises into it. start() connects asynchronously (a broker
not there is retried, not an error); event() and station_state() only queue. Events and state changes
share one queue and go out in the order they came (the "online" and a state said again go first). The
queue is bounded (max_queue messages; the oldest dropped first and counted in `dropped`; when the
dropped one was a station's latest state, that state is said again, so the retained one is never
left stale); at most INFLIGHT messages are handed to paho at a time. A broker that goes away: paho
reconnects with a bounded back-off (RECONNECT_MIN_S .. RECONNECT_MAX_S), the messages wait in the
queue and go out after the reconnect, those paho held unacknowledged taken back first, in their order
(QoS 1: a message the broker got but did not acknowledge may arrive twice). The connection lost /
back is one line through `log` per change, never per retry. close() ends it all within its timeout.
"""

from __future__ import annotations

import json
import ssl
import threading
import time
from collections import deque
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any, Callable, NamedTuple
from urllib.parse import unquote, urlsplit

from profidrive_cli import UsageError
from profidrive_cli.monitor.model import MonEvent

if TYPE_CHECKING:  # pragma: no cover - typing only; paho is imported in MqttAlarms.__init__
    import paho.mqtt.client as paho_client

#: paho's reconnect back-off, seconds (doubling from min to max)
RECONNECT_MIN_S = 1
RECONNECT_MAX_S = 30
#: messages handed to paho and not yet acknowledged, at most
INFLIGHT = 20
#: the MQTT keepalive, seconds: a broker gone silently is noticed within about 1.5 times this
KEEPALIVE_S = 30
#: a TCP connect attempt, seconds
CONNECT_TIMEOUT_S = 5.0

DEFAULT_PREFIX = "pdrive"
MISSING_EXTRA = "--mqtt needs the mqtt extra: pip install 'profidrive-cli[mqtt]'"
OLD_PAHO = "--mqtt needs paho-mqtt 2.2 or newer: pip install -U 'profidrive-cli[mqtt]'"


@dataclass(frozen=True)
class MqttTarget:
    """A parsed --mqtt URL."""
    host: str
    port: int
    prefix: str
    tls: bool = False
    username: str | None = None
    password: str | None = None

    def where(self) -> str:
        return f"{'mqtts' if self.tls else 'mqtt'}://{self.host}:{self.port}"


def parse_url(url: str) -> MqttTarget:
    """`mqtt://[user[:password]@]host[:port][/topic/prefix]` (or mqtts://) -> MqttTarget.
    Raises UsageError (one line naming --mqtt) for anything else."""
    def bad(what: str) -> UsageError:
        return UsageError(f"--mqtt {url!r}: {what} (expected mqtt://[user[:password]@]host[:port][/prefix])")

    try:
        parts = urlsplit(url)
    except ValueError as exc:
        raise bad(str(exc)) from None
    scheme = parts.scheme.lower()
    if scheme not in ("mqtt", "mqtts"):
        raise bad(f"scheme {parts.scheme!r} is not mqtt or mqtts" if parts.scheme else "no mqtt:// scheme")
    if parts.query or parts.fragment:
        raise bad("no ?query or #fragment allowed")
    try:
        port_or_none = parts.port
    except ValueError:
        raise bad("the port is not a number from 1 to 65535") from None
    host = parts.hostname
    if not host:
        raise bad("no host")
    port = port_or_none if port_or_none is not None else (8883 if scheme == "mqtts" else 1883)
    if not 1 <= port <= 65535:
        raise bad("the port is not a number from 1 to 65535")
    prefix = unquote(parts.path).strip("/") or DEFAULT_PREFIX
    if "+" in prefix or "#" in prefix or "//" in prefix:
        raise bad(f"topic prefix {prefix!r} has a wildcard or an empty level")
    username = unquote(parts.username) if parts.username is not None else None
    password = unquote(parts.password) if parts.password is not None else None
    if password is not None and not username:
        raise bad("a password without a user")
    return MqttTarget(host=host, port=port, prefix=prefix, tls=scheme == "mqtts",
                      username=username, password=password)


def _topic_level(value: str) -> str:
    """One topic level from free text: no separators or wildcards."""
    cleaned = "".join("_" if c in "/+#\0" else c for c in value)
    return cleaned or "_"


def iso_time(t: float) -> str:
    return datetime.fromtimestamp(t, timezone.utc).isoformat(timespec="milliseconds")


def event_topic(prefix: str, ev: MonEvent) -> str:
    station = "bus" if ev.station is None else str(ev.station)
    return f"{prefix}/event/{_topic_level(ev.kind)}/{station}"


def event_payload(ev: MonEvent) -> str:
    doc = ev.as_dict()
    doc["time"] = iso_time(ev.t)
    return json.dumps(doc, separators=(",", ":"))


def _print_log(line: str) -> None:
    print(line, flush=True)


class _Msg(NamedTuple):
    """One message for the broker. `station`: the station of a state message (None: an event or
    the status); `counted`: counted in `published` when acknowledged (not the status)."""
    topic: str
    payload: str
    retain: bool
    station: int | None = None
    counted: bool = True


class MqttAlarms:
    """The monitor's events and station states to an MQTT broker (see the module's topic layout).

    Attributes read by the service and the live view: `connected` (a session with the broker is up),
    `published` (events and states the broker acknowledged), `dropped` (events and state changes
    dropped from the full queue, oldest first, or refused by paho)."""

    def __init__(self, url: str, client_id: str | None = None,
                 log: Callable[[str], None] = _print_log, max_queue: int = 1000) -> None:
        """Parse `url` (UsageError when bad), load paho (UsageError when the extra is missing or
        older than 2.2) and set the client up; nothing is connected before start()."""
        self.target = parse_url(url)
        if max_queue < 1:
            raise UsageError(f"--mqtt: the queue must hold at least 1 event, not {max_queue}")
        try:
            import paho.mqtt.client as mqtt
            from paho.mqtt.enums import CallbackAPIVersion
        except ImportError:
            raise UsageError(MISSING_EXTRA) from None
        if not hasattr(mqtt.Client, "drop_out_messages"):   # paho-mqtt 2.2
            raise UsageError(OLD_PAHO)
        self._log = log
        self.max_queue = max_queue
        self.connected = False
        self.published = 0
        self.dropped = 0
        self._prefix = self.target.prefix
        self._status_topic = f"{self._prefix}/status"
        # the lock over everything below; a Condition the sender waits on
        self._lock = threading.Condition()
        # held by the sender from taking a message to noting its mid, and by _on_connect while it
        # takes paho's unacknowledged messages back: no publish() runs while they are taken
        self._send_lock = threading.Lock()
        self._queue: deque[_Msg] = deque()      # events and state changes, in the order they came
        self._states: dict[int, tuple[str, str | None, bool | None, float]] = {}   # the latest each
        # state messages of a station queued or handed to paho and not acknowledged yet
        self._unacked_states: dict[int, int] = {}
        # stations whose latest state is to be said again (after a reconnect, or when the queue
        # dropped their latest change); a dict as an ordered set, at most one entry per station
        self._resend: dict[int, None] = {}
        self._announce = False                  # "online" to publish (set at every connect)
        self._inflight: dict[int, _Msg] = {}    # mid -> the message handed to paho, not acknowledged
        self._early: set[int] = set()           # acknowledged before publish() returned its mid
        self._ever_connected = False
        self._lost_reported = False            # "not reachable" / "lost" said since the last connect
        self._refused: str | None = None
        self._overflow_reported = False
        self._closing = False
        self._started = False
        self._sender: threading.Thread | None = None

        client = mqtt.Client(CallbackAPIVersion.VERSION2,
                             client_id=client_id or f"pdrive-monitor-{id(self):x}"[:23],
                             protocol=mqtt.MQTTv311, clean_session=True)
        client.suppress_exceptions = True
        client.connect_timeout = CONNECT_TIMEOUT_S
        client.reconnect_delay_set(RECONNECT_MIN_S, RECONNECT_MAX_S)
        client.max_inflight_messages_set(INFLIGHT)
        client.will_set(self._status_topic, "offline", qos=1, retain=True)
        if self.target.username:
            client.username_pw_set(self.target.username, self.target.password)
        if self.target.tls:
            client.tls_set(cert_reqs=ssl.CERT_REQUIRED)
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_connect_fail = self._on_connect_fail
        client.on_publish = self._on_publish
        self._client: paho_client.Client = client

    # -- the monitor's side ------------------------------------------------------------------

    def start(self) -> None:
        """Connect in the background (paho's network thread and a sender thread); never blocks,
        a broker not there is retried."""
        if self._started:
            return
        self._started = True
        try:
            self._client.connect_async(self.target.host, self.target.port, keepalive=KEEPALIVE_S)
            self._client.loop_start()
        except Exception as exc:  # noqa: BLE001 - a bad host or TLS setup is a line, not a traceback
            self._log(f"MQTT {self.target.where()}: cannot start ({exc}); alarms off")
            return
        self._sender = threading.Thread(target=self._send_loop, name="pdrive-mqtt-send", daemon=True)
        self._sender.start()

    def event(self, ev: MonEvent) -> None:
        """Queue one event for PREFIX/event/KIND/STATION; never blocks. A full queue drops its
        oldest message (counted in `dropped`)."""
        self._put(_Msg(event_topic(self._prefix, ev), event_payload(ev), False))

    def station_state(self, station: int, state: str, drive_state: str | None, fault: bool | None,
                      t: float | None = None) -> None:
        """Queue PREFIX/station/N/state (retained) when state, drive_state or fault changed since
        the last call for this station: every change, in order with the events; never blocks.
        `t`: the time of the state (the record's; time.time() when not given)."""
        when = time.time() if t is None else t
        with self._lock:
            if self._closing:
                return
            old = self._states.get(station)
            if old is not None and old[:3] == (state, drive_state, fault):
                return
            self._states[station] = (state, drive_state, fault, when)
            # this change carries the latest state: no need to say an older one again
            self._resend.pop(station, None)
        self._put(self._state_message(station, (state, drive_state, fault, when)))

    def close(self, timeout: float = 2.0) -> None:
        """Flush what can go in about half of `timeout`, publish "offline", disconnect and stop the
        threads; returns within about `timeout` seconds whatever the broker does."""
        deadline = time.monotonic() + max(timeout, 0.0)
        with self._lock:
            if self._closing:
                return
            self._closing = True
            self._flush_until = time.monotonic() + max(timeout, 0.0) / 2
            self._lock.notify_all()
        if not self._started:
            return
        sender = self._sender
        if sender is not None:
            sender.join(max(0.0, self._flush_until - time.monotonic()) + 0.1)
        try:
            if self.connected:
                info = self._client.publish(self._status_topic, "offline", qos=1, retain=True)
                info.wait_for_publish(max(0.05, (deadline - time.monotonic()) * 0.7))
        except Exception:  # noqa: BLE001 - the will says offline when this did not go out
            pass
        try:
            self._client.disconnect()
        except Exception:  # noqa: BLE001
            pass
        # paho's loop_stop() joins without a bound: give it what is left, in a thread of its own
        stopper = threading.Thread(target=self._client.loop_stop, name="pdrive-mqtt-stop", daemon=True)
        stopper.start()
        stopper.join(max(0.05, deadline - time.monotonic()))
        with self._lock:
            self.connected = False

    # -- inside ---------------------------------------------------------------------------------

    _flush_until = 0.0

    def _say(self, line: str) -> None:
        try:
            self._log(line)
        except Exception:  # noqa: BLE001 - a log that fails must not stop the alarms
            pass

    def _state_message(self, station: int,
                       record: tuple[str, str | None, bool | None, float]) -> _Msg:
        state, drive_state, fault, when = record
        payload = json.dumps({"state": state, "drive_state": drive_state, "fault": fault, "t": when},
                             separators=(",", ":"))
        return _Msg(f"{self._prefix}/station/{station}/state", payload, True, station)

    def _put(self, msg: _Msg) -> None:
        """Queue one message, the oldest dropped when full."""
        with self._lock:
            if self._closing:
                return
            if msg.station is not None:
                self._unacked_states[msg.station] = self._unacked_states.get(msg.station, 0) + 1
            self._queue.append(msg)
            note = self._trim()
            self._lock.notify_all()
        if note:
            self._say(note)

    def _trim(self) -> str:
        """Drop the oldest messages beyond max_queue (under the lock); the line to say, or ""."""
        note = ""
        while len(self._queue) > self.max_queue:
            self._forget(self._queue.popleft())
            if not self._overflow_reported:
                self._overflow_reported = True
                note = f"MQTT: queue full ({self.max_queue} messages), dropping the oldest"
        return note

    def _forget(self, msg: _Msg, resend: bool = True) -> None:
        """A message that will not go out (under the lock): counted in `dropped`; when it was its
        station's latest unacknowledged state, that state is said again (`resend`)."""
        self.dropped += 1
        if msg.station is not None and self._settled(msg.station) and resend:
            self._resend[msg.station] = None

    def _settled(self, station: int) -> bool:
        """One state message of `station` acknowledged or dropped (under the lock): True when it
        was the last one queued or in flight."""
        left = self._unacked_states.get(station, 0) - 1
        if left > 0:
            self._unacked_states[station] = left
            return False
        self._unacked_states.pop(station, None)
        return True

    def _acked(self, msg: _Msg) -> None:
        """The broker acknowledged `msg` (under the lock)."""
        if msg.counted:
            self.published += 1
        if msg.station is not None:
            self._settled(msg.station)

    def _has_work(self) -> bool:
        return self._announce or bool(self._resend) or bool(self._queue)

    def _next(self) -> _Msg | None:
        """The next message to hand to paho, or None. Under the lock."""
        if not self.connected or len(self._inflight) >= INFLIGHT:
            return None
        if self._announce:
            self._announce = False
            return _Msg(self._status_topic, "online", True, None, counted=False)
        if self._resend:
            station = next(iter(self._resend))
            del self._resend[station]
            self._unacked_states[station] = self._unacked_states.get(station, 0) + 1
            return self._state_message(station, self._states[station])
        if self._queue:
            return self._queue.popleft()
        return None

    def _send_loop(self) -> None:
        while True:
            with self._lock:
                while True:
                    if self._closing and (time.monotonic() >= self._flush_until or not self.connected
                                          or not self._has_work()):
                        return
                    if (self.connected and len(self._inflight) < INFLIGHT) and self._has_work():
                        break
                    self._lock.wait(0.5)
            with self._send_lock:
                with self._lock:
                    msg = self._next()
                if msg is None:
                    continue
                try:
                    info = self._client.publish(msg.topic, msg.payload, qos=1, retain=msg.retain)
                except Exception as exc:  # noqa: BLE001 - paho refused it (a size, a topic): dropped
                    with self._lock:
                        self._forget(msg, resend=False)
                    self._say(f"MQTT: publishing to {msg.topic} failed ({exc}); dropped")
                    continue
                with self._lock:
                    if info.mid in self._early:
                        self._early.discard(info.mid)
                        self._acked(msg)
                    else:
                        # NO_CONN included: paho keeps it, _on_connect takes it back
                        self._inflight[info.mid] = msg

    # paho's callbacks (its network thread): they take our locks only; _on_connect also takes
    # paho's unacknowledged messages back (drop_out_messages, which only takes paho's own lock)

    def _on_connect(self, client: Any, userdata: Any, flags: Any, reason_code: Any,
                    properties: Any = None) -> None:
        failed = bool(getattr(reason_code, "is_failure", False))
        if failed:
            text = str(reason_code)
            if text != self._refused:
                self._refused = text
                self._say(f"MQTT {self.target.where()}: the broker refused the connection ({text}); retrying")
            return
        with self._send_lock:
            # what paho still holds from the last session would be resent by paho after this
            # callback, behind anything our sender hands it meanwhile: take it back and put it at the
            # front of our queue, so that events and each station's states go out in their order
            held = client.drop_out_messages()
            with self._lock:
                for m in reversed(held):
                    msg = self._inflight.pop(m.mid, None)
                    if msg is not None and msg.counted:   # not the status: "online" is said anew
                        self._queue.appendleft(msg)
                self._inflight.clear()
                self._early.clear()
                note = self._trim()
                self.connected = True
                self._announce = True
                # a broker that restarted without persistence lost the retained states: say the
                # latest of each station again, unless a newer change of it is queued anyway
                for station in self._states:
                    if station not in self._unacked_states:
                        self._resend[station] = None
                was_lost = self._lost_reported or self._refused is not None
                first = not self._ever_connected
                self._ever_connected = True
                self._lost_reported = False
                self._refused = None
                self._overflow_reported = False
                queued = len(self._queue)
                self._lock.notify_all()
        if note:
            self._say(note)
        if first and not was_lost:
            self._say(f"MQTT {self.target.where()}: connected, topics under {self._prefix}/")
        else:
            self._say(f"MQTT {self.target.where()}: broker back, sending {queued} queued messages")

    def _on_disconnect(self, client: Any, userdata: Any, flags: Any, reason_code: Any,
                       properties: Any = None) -> None:
        with self._lock:
            was = self.connected
            self.connected = False
            if self._closing or not was or self._lost_reported:
                return
            self._lost_reported = True
        self._say(f"MQTT {self.target.where()}: connection lost ({reason_code}); events queued "
                  f"(at most {self.max_queue}), reconnecting")

    def _on_connect_fail(self, client: Any, userdata: Any) -> None:
        with self._lock:
            if self._closing or self._lost_reported:
                return
            self._lost_reported = True
            ever = self._ever_connected
        if not ever:
            self._say(f"MQTT {self.target.where()}: broker not reachable; events queued "
                      f"(at most {self.max_queue}), retrying")

    def _on_publish(self, client: Any, userdata: Any, mid: int, reason_code: Any = None,
                    properties: Any = None) -> None:
        with self._lock:
            msg = self._inflight.pop(mid, None)
            if msg is not None:
                self._acked(msg)
            else:   # before the sender noted its mid (or close()'s "offline": one stray mid)
                self._early.add(mid)
            self._lock.notify_all()
