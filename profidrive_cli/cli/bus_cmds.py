"""pdrive scan / diag / io."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, overload

import click
from rich.markup import escape
from rich.table import Table

from profidrive_cli import BusError, UsageError
from profidrive_cli.cli.common import (BusOptions, bus_options, confirm_real_port, emit_json, err, hex_option, out,
                                       station_address)
from profidrive_cli.cli.jsonout import ident_fields
from profidrive_cli.cli.names import device_name
from profidrive_cli.dp.cfg import CfgError, decode_cfg
from profidrive_cli.fdl.timing import BAUD_NAMES
from profidrive_cli.link.base import LinkLost

if TYPE_CHECKING:
    from collections.abc import Callable
    from types import FrameType

    from profidrive_cli.bustools.baseline import NetworkRecord
    from profidrive_cli.dp.poller import Master
    from profidrive_cli.dp.services import SlaveDiag
    from profidrive_cli.dp.station import StationMachine
    from profidrive_cli.gsd.model import Gsd
    from profidrive_cli.gsd.slavedata import SlaveLayout

    #: what signal.signal takes and gives back: a function, SIG_DFL / SIG_IGN, or None
    _Handler = Callable[[int, FrameType | None], Any] | int | None


def _diag_json(d: SlaveDiag | None) -> dict[str, Any] | None:
    if d is None:
        return None
    blocks = _ext_blocks(d)
    return {"st1": d.st1, "st2": d.st2, "st3": d.st3, "master": None if d.master == 0xFF else d.master,
            **ident_fields(d.ident), "flags": d.flags(), "ready": d.ready,
            "ext": d.ext.hex(" "), "ext_blocks": [b["text"] for b in blocks], "ext_decoded": blocks}


def _ext_blocks(d: SlaveDiag) -> list[dict[str, Any]]:
    """The extended diagnosis block by block, decoded as sniff decodes it (dp/du_decode.ext_block:
    the DP-V1 status / alarm blocks included)."""
    from profidrive_cli.dp.du_decode import ext_block
    return [ext_block(b) for b in d.ext_blocks()]


@overload
def _cfg_json(cfg: bytes) -> list[dict[str, Any]]: ...
@overload
def _cfg_json(cfg: None) -> None: ...
@overload
def _cfg_json(cfg: bytes | None) -> list[dict[str, Any]] | None: ...
def _cfg_json(cfg: bytes | None) -> list[dict[str, Any]] | None:
    if cfg is None:
        return None
    try:
        return [{"octets": m.raw.hex(" "), "inputs": m.inputs, "outputs": m.outputs,
                 "text": m.describe()} for m in decode_cfg(cfg)]
    except CfgError as e:
        return [{"octets": cfg.hex(" "), "error": str(e)}]


@click.command("scan")
@click.option("--from", "first", default=0, show_default=True, type=click.IntRange(0, 126))
@click.option("--to", "last", default=126, show_default=True, type=click.IntRange(0, 126))
@click.option("--gsd-dir", default=None, help="Extra GSD folder for naming stations.")
@click.option("--watch", is_flag=True,
              help="Keep polling: a live list refreshed in place, states in colour, counters and their rates.")
@click.option("--interval", default=1.0, show_default=True, type=click.FloatRange(min=0.05),
              help="--watch: seconds between refreshes.")
@click.option("--duration", default=None, type=click.FloatRange(min=0, min_open=True),
              help="--watch: stop after watching this many seconds, counted after the first scan "
                   "(default: until Ctrl-C).")
@click.option("--quick", is_flag=True,
              help="One FDL status per address, no second pass over the silent ones: half the "
                   "requests on an empty bus, but a slave still searching the baud rate is found "
                   "only when the traffic before its request woke it.")
@click.option("--save", "save_path", default=None, metavar="FILE",
              help="Record the accepted network (stations, idents, Get_Cfg, counters, reply times) "
                   "to FILE (.yaml/.yml: YAML, else JSON).")
@click.option("--compare", "compare_path", default=None, metavar="FILE",
              help="Scan the range of a --save FILE and report what changed; exit 1 on any difference.")
@click.option("--junit", default=None, metavar="FILE", help="--compare: also write a JUnit XML report.")
@bus_options
def scan_cmd(opts: BusOptions, first: int, last: int, gsd_dir: str | None, watch: bool,
             interval: float, duration: float | None, quick: bool, save_path: str | None,
             compare_path: str | None, junit: str | None) -> None:
    """Live list: every station on the bus, its type, ident and DP state."""
    from profidrive_cli.dp.scan import scan
    if first > last:
        raise UsageError(f"--from {first} is above --to {last}")
    if not watch and duration is not None:
        raise UsageError("--duration goes with --watch")
    base = _baseline_options(watch, save_path, compare_path, junit)
    opts.require_port()
    master = opts.open_master()
    if base is None and save_path is not None:
        from profidrive_cli.cli import scan_baseline
        raise SystemExit(scan_baseline.save(opts, master, first, last, save_path, quick, gsd_dir))
    if base is not None and compare_path is not None:      # (a baseline comes with --compare only)
        from profidrive_cli.cli import scan_baseline
        raise SystemExit(scan_baseline.compare(opts, master, base, compare_path, junit, quick))
    if watch:
        from profidrive_cli.cli.scan_watch import watch as run_watch
        raise SystemExit(run_watch(opts, master, first, last, interval, duration, gsd_dir))
    used_baud = opts.baud_rate()
    try:
        if opts.json or not err.is_terminal:
            result = scan(master, first, last, quick=quick)
        else:
            from rich.progress import Progress      # only on a terminal: rich.progress is slow to import
            with Progress(console=err, transient=True) as prog:
                task = prog.add_task(f"scanning at {BAUD_NAMES[used_baud]}", total=last - first + 1)
                result = scan(master, first, last, progress=lambda a: prog.advance(task),
                              quick=quick)
        # corrupt telegrams and noise runs seen while probing (every address, found or not)
        noise = sum(c.illegal for c in master.fdl.counters.values())
    finally:
        master.link.close()
    if opts.json:
        emit_json({"port": opts.port, "baud": used_baud, "line_noise": noise,
                   "echo": getattr(master.link, "echo_detected", None), "stations": [
            {"station": e.address, "type": e.station_type, **ident_fields(e.ident),
             "state": e.diag.state_words(opts.master_address) if e.diag else e.error,
             "device": device_name(e.ident, gsd_dir) if e.ident is not None else "",
             "diag": _diag_json(e.diag), "counters": e.counters,
             "unanswered_before": e.unanswered} for e in result]})
        if not result:
            raise SystemExit(1)         # the same exit code as the table: nobody answered
        return
    if noise:
        err.print(f"the line is noisy: {noise} corrupt or unexpected telegram(s) during the scan "
                  f"(check termination, shielding, the baud rate and other masters)")
    if not result:
        out.print(f"no station answered on {opts.port} at {BAUD_NAMES[used_baud]}"
                  + opts.silence_hint(master.link, baud_auto=True))
        raise SystemExit(1)
    t = Table(title=f"{opts.port} at {BAUD_NAMES[used_baud]}: {len(result)} station(s)")
    from profidrive_cli.fdl.master import format_counters
    for col in ("addr", "type", "ident", "DP state", "device", "counters"):
        t.add_column(col)
    for e in result:
        t.add_row(str(e.address), e.station_type,
                  f"0x{e.ident:04X}" if e.ident is not None else "",
                  e.diag.state_words(opts.master_address) if e.diag else e.error,
                  device_name(e.ident, gsd_dir) if e.ident is not None else "",
                  format_counters(e.counters))
    out.print(t)
    for e in result:
        if e.unanswered:
            out.print(late_answer(e.address, e.unanswered))


def _baseline_options(watch: bool, save_path: str | None, compare_path: str | None,
                      junit: str | None) -> NetworkRecord | None:
    """--save / --compare / --junit checked, their files too, before the port opens: the baseline of
    --compare (None without it)."""
    if save_path is not None and compare_path is not None:
        raise UsageError("--save and --compare go one at a time")
    if watch and (save_path is not None or compare_path is not None):
        raise UsageError("--watch does not go with --save or --compare")
    if junit is not None and compare_path is None:
        raise UsageError("--junit goes with --compare")
    if compare_path is not None:
        from click.core import ParameterSource
        ctx = click.get_current_context()
        if any(ctx.get_parameter_source(p) == ParameterSource.COMMANDLINE for p in ("first", "last")):
            raise UsageError("--compare scans the addresses the baseline recorded: --from / --to go "
                             "with --save")
    if save_path is None and compare_path is None:
        return None
    from profidrive_cli.cli.scan_baseline import check_paths
    return check_paths(save_path, compare_path, junit)


def late_answer(address: int, unanswered: int) -> str:
    """The words for a station that answered only after `unanswered` FDL status requests."""
    return (f"station {address} answered after {unanswered} unanswered request"
            f"{'' if unanswered == 1 else 's'} (baud-rate search)")


@click.command("diag")
@click.argument("address", type=int)
@click.option("--gsd-dir", default=None, help="Extra GSD folder for diagnosis texts.")
@bus_options
def diag_cmd(opts: BusOptions, address: int, gsd_dir: str | None) -> None:
    """The whole Slave_Diag of one station decoded, and its Get_Cfg."""
    station_address(address)
    master = opts.open_master(address=address)
    try:
        d = master.slave_diag(address, wake=True)
        if d is None:
            raise BusError(f"station {address} does not answer on {opts.port}"
                           f"{opts.silence_hint(master.link)}")
        cfg = master.get_cfg(address)
        counters = master.fdl.counters_for(address).as_dict()
    finally:
        master.link.close()
    unit = _unit_diag_texts(d, gsd_dir)
    if opts.json:
        emit_json({"station": address, **ident_fields(d.ident), "state": d.state_words(opts.master_address),
                   "device": device_name(d.ident, gsd_dir), "diag": _diag_json(d),
                   "explain": d.explain(), "unit_diag": unit, "cfg": _cfg_json(cfg),
                   "counters": counters})
        return
    out.print(f"[bold]station {address}[/bold]: {d.state_words(opts.master_address)}"
              f"  (ident 0x{d.ident:04X} {device_name(d.ident, gsd_dir)})")
    out.print(f"raw: {d.encode().hex(' ')}")
    for line in d.explain():
        out.print(f"  {line}")
    for b in _ext_blocks(d):
        out.print(f"  ext: {escape(b['text'])}")
    for line in unit:
        out.print(f"  unit diag: {line}")
    if cfg is not None:
        out.print(f"Get_Cfg: {cfg.hex(' ') or '(empty)'}")
        for m in _cfg_json(cfg):
            out.print(f"  {m.get('octets')}: {m.get('text', m.get('error'))}")
    from profidrive_cli.fdl.master import format_counters
    out.print(f"counters: {format_counters(counters)}")


def _unit_diag_texts(d: SlaveDiag, gsd_dir: str | None) -> list[str]:
    if not any(b.kind == "device" for b in d.ext_blocks()):
        return []
    from profidrive_cli.gsd.interp import decode_unit_diag
    from profidrive_cli.gsd.library import find_by_ident
    g = find_by_ident(d.ident, gsd_dir)
    if g is None:
        return []
    return decode_unit_diag(g, d.ext)


@click.command("io")
@click.argument("address", type=int)
@click.option("--cfg", "cfg_hex", default=None, help="Chk_Cfg identifier octets, hex.")
@click.option("--ident", "ident_hex", default=None, help="Ident number (default: from the diagnosis).")
@click.option("--prm", "prm_hex", default=None, help="Set_Prm user-parameter octets, hex.")
@click.option("--out", "out_hex", default=None, help="Output octets to send, hex (default zeros).")
@click.option("--count", default=5, show_default=True, type=click.IntRange(1, 10**9))
@click.option("--watchdog", "wd_ms", default=500, show_default=True, type=click.IntRange(10, 650000),
              help="Slave watchdog in ms (always armed).")
@click.option("--gsd", "gsd_file", default=None, help="GSD file or ident for --module.")
@click.option("--module", "modules", multiple=True, metavar="NAME",
              help="GSD module name (with --gsd); repeat it for each slot, in slot order.")
@click.option("--yes", is_flag=True, help="Do not ask before sending --out on a real port.")
@click.option("--stop-timeout", "stop_timeout", default=30.0, show_default=True,
              type=click.FloatRange(0.0, 3600.0), metavar="S",
              help="At the end, hold the safe state at most S s waiting for the inputs to settle.")
@bus_options
def io_cmd(opts: BusOptions, address: int, cfg_hex: str | None, ident_hex: str | None,
           prm_hex: str | None, out_hex: str | None, count: int, wd_ms: int, gsd_file: str | None,
           modules: tuple[str, ...], yes: bool, stop_timeout: float) -> None:
    """Bring any DP slave to Data_Exchange with a given configuration and show its inputs.

    It ends like a PLC going to STOP: outputs all zero and Global_Control Clear_Data for at least
    one watchdog period (and, after non-zero --out, until the inputs settle), then the station is
    released. Also on Ctrl-C, SIGTERM and errors.
    """
    from profidrive_cli.dp.cfg import io_sizes
    from profidrive_cli.dp.station import SlaveConfig
    station_address(address)
    cfg = hex_option(cfg_hex, "--cfg")
    prm = hex_option(prm_hex, "--prm") or b""
    if gsd_file:
        cfg_g, prm_g, ident_g = _from_gsd(gsd_file, modules)
        cfg = cfg if cfg is not None else cfg_g
        prm = prm or prm_g
        ident_hex = ident_hex or f"{ident_g:04X}"
    if not cfg:
        raise UsageError("give the configuration with --cfg HEX (or --gsd FILE --module NAME)")
    try:
        decode_cfg(cfg)
        _, output_len = io_sizes(cfg)
    except (CfgError, ValueError) as e:
        raise UsageError(f"--cfg: {e}") from None
    ident = None
    if ident_hex:
        try:
            ident = int(ident_hex, 16)
        except ValueError:
            raise UsageError(f"--ident: not hex: {ident_hex}") from None
    outputs = hex_option(out_hex, "--out")
    if outputs is not None and len(outputs) != output_len:
        raise UsageError(f"--out has {len(outputs)} octets, the configuration has "
                         f"{output_len} output octets")
    port = opts.require_port()
    if outputs is not None:
        # any --out on a real port asks: whatever the station drives acts on these octets
        confirm_real_port(port, yes, f"send outputs {outputs.hex(' ') or '(none)'} to station "
                                     f"{address} on {port} (a drive there may start)",
                          cancelled="cancelled: nothing was sent")
    moved = outputs is not None and any(outputs)
    master = opts.open_master(address=address)
    ender = _SafeEnd(master, address, wd_ms / 1000.0, stop_timeout, wait_settle=moved)
    try:
        with _terminations_raise():
            try:
                if ident is None:
                    d = master.slave_diag(address, wake=True)
                    if d is None:
                        raise BusError(f"station {address} does not answer on {opts.port}"
                                       f"{opts.silence_hint(master.link)}")
                    ident = d.ident
                sc = SlaveConfig(ident=ident, cfg=cfg, user_prm=prm, wd_ms=wd_ms)
                master.add_station(address, sc)
                by_module = _gsd_layout(ident, gsd_file, cfg, prm)   # GSD work before the watchdog runs
                try:
                    master.bring_up(address, timeout=3.0, fail_fast=True)
                except BusError as e:
                    raise BusError(f"{e}{_prm_hint(master.stations[address].state, prm)}") from None
                lay = _by_module(master, address, by_module, prm, opts.json)
                for i in range(count):
                    inputs = master.exchange(address, outputs)
                    if opts.json:
                        emit_json({"event": "cycle", "station": address, "cycle": i,
                                   "inputs": inputs.hex(" "),
                                   **({} if lay is None else {"modules": _values(lay, "in", inputs)})})
                    else:
                        _row(f"{i:>5}  in: {inputs.hex(' ') or '(none)'}")
                        if lay is not None and len(lay.split("in", inputs)) > 1:   # one: the line above
                            for m in _values(lay, "in", inputs):
                                _row(f"       slot {m['slot']} {m['name']}: {m['octets']}")
            except LinkLost:
                ender.link_lost = True
                raise
            finally:
                ender.run()
    except _Terminated as e:
        err.print(f"terminated (signal {e.signum})")
        raise SystemExit(128 + e.signum) from None
    finally:
        master.link.close()
    if ender.problem:
        raise BusError(f"station {address}: {ender.problem}")


def _prm_hint(state: str, prm: bytes) -> str:
    """After a start-up that ended in a parameter fault: what io sent, and how to give the station's
    own user parameters (a slave checks their length and content; reference §3.1)."""
    from profidrive_cli.dp.station import PRM_FAULT
    if state != PRM_FAULT:
        return ""
    return (f"; the Set_Prm carried {len(prm)} octet(s) of user parameters: give the station's with "
            f"--prm HEX (or --gsd FILE --module NAME)")


def _gsd_layout(ident: int, gsd_file: str | None, cfg: bytes,
                prm: bytes) -> tuple[Gsd, SlaveLayout] | None:
    """(GSD, the layout of `cfg`) for io's by-module view: the GSD from --gsd, else the library by
    ident; None without one. Done before bring-up, so that parsing a large GSD never delays the
    first Data_Exchange past the watchdog."""
    from profidrive_cli.gsd.library import find_by_ident, load_gsd
    from profidrive_cli.gsd.slavedata import layout
    try:
        g = load_gsd(gsd_file) if gsd_file else find_by_ident(ident)
    except UsageError:
        return None
    return None if g is None else (g, layout(g, cfg, prm or None))


def _by_module(master: Master, address: int, by_module: tuple[Gsd, SlaveLayout] | None, prm: bytes,
               as_json: bool) -> SlaveLayout | None:
    """The station's data by module (gsd/slavedata.py) from its Get_Cfg (read once after bring-up;
    the layout of the configuration sent when they agree); None without a GSD or a Get_Cfg. Text
    output: the layout once, before the cycles."""
    if by_module is None:
        return None
    g, lay = by_module
    real = master.get_cfg(address)
    if real is None:
        return None
    if real != lay.cfg:
        from profidrive_cli.gsd.slavedata import layout
        try:
            lay = layout(g, real, prm or None)
        except CfgError:
            return None
    if not as_json:
        _row(f"station {address} by module ({g.title}, Get_Cfg {real.hex(' ')}):")
        for line in lay.describe():
            _row(f"  {line}")
    return lay


def _values(lay: SlaveLayout, direction: str, data: bytes) -> list[dict[str, Any]]:
    from profidrive_cli.gsd.slavedata import values
    return values(lay, direction, data)


def _row(text: str) -> None:
    """One per-cycle text row, written plainly: through rich a row cost about 60 µs (markup,
    measuring, rendering) for text that has none of it. Flushed, so a pipe sees each row."""
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


class _Terminated(BaseException):
    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)


@contextlib.contextmanager
def _terminations_raise() -> Iterator[None]:
    """SIGTERM raises _Terminated in the main thread while the block runs (SIGINT: KeyboardInterrupt)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_term(signum: int, frame: FrameType | None) -> None:
        raise _Terminated(signum)
    old = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


class _SafeEnd:
    """How io leaves a station, like a PLC going to STOP: outputs all zero and Global_Control
    Clear_Data (reference §3.5), kept up by Data_Exchange (the watchdog stays fed) for at least one
    watchdog period and — after non-zero outputs — until the inputs have not changed for one
    watchdog period (a drive reports its speed falling), at most `stop_timeout` s; then Set_Prm with
    Unlock_Req. A drive stopped this way is stopped, not tripped by communication loss.

    While it runs, a further Ctrl-C / SIGTERM only shortens the wait for the inputs to settle."""

    PACE_S = 0.01

    def __init__(self, master: Master, address: int, wd_s: float, stop_timeout: float,
                 wait_settle: bool) -> None:
        self.master = master
        self.address = address
        self.wd_s = wd_s
        self.stop_timeout = max(stop_timeout, wd_s)
        self.wait_settle = wait_settle
        self.link_lost = False
        self.problem: str | None = None
        self.hurry = False
        self.done = False

    def run(self) -> None:
        if self.done:
            return
        self.done = True
        if self.link_lost:
            err.print(f"station {self.address}: link lost: nothing can be sent; the station's "
                      f"watchdog ({self.wd_s * 1000:g} ms) sets its outputs to the safe state")
            return
        st = self.master.stations.get(self.address)
        if st is None:
            return
        old = self._guard()
        try:
            self._hold(st)
        except BaseException as e:                 # never mask what ended the exchange
            if not isinstance(e, Exception):
                self.hurry = True
            self.problem = f"the safe state could not be held ({e})"
            err.print(f"station {self.address}: {self.problem}")
        finally:
            try:
                self.master.release(self.address)
            except Exception:
                pass
            self._unguard(old)

    def _hold(self, st: StationMachine) -> None:
        from profidrive_cli.dp import services as S
        m, link = self.master, self.master.link
        zeros = bytes(st.output_len)
        st.set_outputs(zeros)
        if not st.in_data_exchange:
            return                                     # never reached data exchange: nothing to hold
        m.global_control(S.GC_CLEAR, da=self.address)
        t0 = link.now()
        next_gc = t0 + self.wd_s / 2
        prev, last_change = None, t0
        while True:
            inputs = m.exchange(self.address, zeros)
            now = link.now()
            if inputs != prev:
                prev, last_change = inputs, now
            if now >= next_gc:                         # a master in CLEAR repeats Global_Control
                m.global_control(S.GC_CLEAR, da=self.address)
                next_gc = now + self.wd_s / 2
            held = now - t0
            if held >= self.wd_s and (not self.wait_settle or self.hurry
                                      or now - last_change >= self.wd_s):
                break
            if held >= self.stop_timeout:
                self.problem = (f"inputs still changing after {held:.1f} s of safe outputs "
                                f"(--stop-timeout {self.stop_timeout:g}); released anyway")
                break
            link.sleep(self.PACE_S)
        err.print(f"station {self.address}: outputs zero and Global_Control Clear for "
                  f"{held:.2f} s, then released")

    def _guard(self) -> dict[signal.Signals, _Handler] | None:
        if threading.current_thread() is not threading.main_thread():
            return None

        def hurry(signum: int, frame: FrameType | None) -> None:
            self.hurry = True
        return {s: signal.signal(s, hurry) for s in (signal.SIGINT, signal.SIGTERM)}

    def _unguard(self, old: dict[signal.Signals, _Handler] | None) -> None:
        for s, h in (old or {}).items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


def _from_gsd(gsd_file: str, modules: tuple[str, ...]) -> tuple[bytes, bytes, int | None]:
    from profidrive_cli.gsd.interp import build_prm
    from profidrive_cli.gsd.library import load_gsd
    g = load_gsd(gsd_file)
    res = build_prm(g, list(modules))
    return res.cfg, res.user_prm, g.ident
