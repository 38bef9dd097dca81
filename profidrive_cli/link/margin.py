"""The OS margin of a link: how much later than its wire time a reply may reach the master.

A master waits for a reply the slot time after its request, plus this margin for what lies between
the line and the process: the OS waking the process (and, over a pty, the process at the other end),
a USB adapter holding received octets until its latency timer runs out, a TCP connection's round
trip. It is paid in full by every request nobody answers -- a scan's empty addresses -- so a fixed
generous margin (20 ms, what pdrive used on every real port) makes a scan over a pty several times
its wire time, while one too small turns late answers into silences.

measure(ser, port) measures it when the port is opened, from what the link can time without a slave:

  wake      the OS's lateness in waking this process now: the largest overshoot of WAKE_SAMPLES
            sleeps of WAKE_SLEEP_S (a reply crosses at most two such wakes: the other end's, a pty's
            simulator or a converter's process on this machine, and ours; counted WAKE_FACTOR = 4
            times, for a load that comes and goes)
  adapter   what the transport itself holds a reply: a USB serial adapter its latency timer (sysfs
            latency_timer, FTDI: 16 ms by default, reference §4.3); socket:// the kernel's smoothed
            round-trip time of the connection (TCP_INFO tcpi_rtt, Linux); a pty nothing (both ends are
            processes on this machine: their wakes are the wake term)

margin = adapter + WAKE_FACTOR x wake, bounded below by FLOOR_S (5 ms: the OS wakes a busy machine's
processes a few ms late now and then; a late answer beyond the margin costs a retry, not a station)
and above by CEILING_S (50 ms: an adapter with the default 16 ms timer and a loaded machine; beyond
that the retries and the scan's second pass cover it). A port whose delays the link cannot tell (a
native UART or USB CDC device without a latency timer, rfc2217://, a plug-in's scheme) keeps the
fixed DEFAULT_S = 20 ms, as before.
"""

from __future__ import annotations

import os
import socket
import struct
import time
from typing import Any

#: the margin of a port whose delays cannot be told (every real port before it was measured)
DEFAULT_S = 0.02
#: the bounds of a measured margin (see the module text)
FLOOR_S = 0.005
CEILING_S = 0.05
#: the OS's wake-up lateness: the largest overshoot of this many short sleeps, counted this often
WAKE_SAMPLES = 4
WAKE_SLEEP_S = 0.0005
WAKE_FACTOR = 4.0
#: struct tcp_info (linux/tcp.h): tcpi_rtt, smoothed round trip in µs, is the u32 at this offset
_TCPI_RTT_OFFSET = 68


def wake_lateness(samples: int = WAKE_SAMPLES, sleep_s: float = WAKE_SLEEP_S) -> float:
    """The largest overshoot, in seconds, of `samples` sleeps of `sleep_s`."""
    worst = 0.0
    for _ in range(samples):
        t = time.monotonic()
        time.sleep(sleep_s)
        worst = max(worst, time.monotonic() - t - sleep_s)
    return worst


def usb_latency_timer(port: str, sysfs: str = "/sys") -> float | None:
    """A USB serial adapter's latency timer in seconds (sysfs), None when the port has none."""
    name = os.path.basename(os.path.realpath(port))
    try:
        with open(os.path.join(sysfs, "bus", "usb-serial", "devices", name, "latency_timer")) as f:
            return int(f.read().strip()) / 1000.0
    except (OSError, ValueError):
        return None


def tcp_rtt(sock: Any) -> float | None:
    """The kernel's smoothed round-trip time of a TCP connection in seconds (Linux TCP_INFO), None
    where the system does not say."""
    opt = getattr(socket, "TCP_INFO", None)
    if opt is None or sock is None:
        return None
    try:
        info = sock.getsockopt(socket.IPPROTO_TCP, opt, 104)
    except (OSError, AttributeError):
        return None
    if len(info) < _TCPI_RTT_OFFSET + 4:
        return None
    rtt_us: int = struct.unpack_from("I", info, _TCPI_RTT_OFFSET)[0]
    return rtt_us / 1e6


def is_pty(port: str) -> bool:
    return "://" not in port and os.path.realpath(port).startswith(("/dev/pts/", "/dev/pty"))


def adapter_delay(ser: Any, port: str) -> float | None:
    """What the transport holds a reply (module text), None when the link cannot tell."""
    if port.startswith("socket://"):
        return tcp_rtt(getattr(ser, "_socket", None))
    if is_pty(port):
        return 0.0
    if "://" not in port:
        return usb_latency_timer(port)
    return None


def bounded(seconds: float) -> float:
    return min(CEILING_S, max(FLOOR_S, seconds))


def measure(ser: Any, port: str) -> float:
    """The OS margin of an open port in seconds (module text): measured and bounded, or DEFAULT_S."""
    adapter = adapter_delay(ser, port)
    if adapter is None:
        return DEFAULT_S
    return bounded(adapter + WAKE_FACTOR * wake_lateness())
