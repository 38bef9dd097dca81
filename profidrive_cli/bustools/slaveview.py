"""Every slave's cyclic data by module in `pdrive sniff`, from the traffic and the GSD library.

SlaveView learns each station from what goes by: the ident from its Set_Prm (octets 4..5) or a
Slave_Diag reply, the Set_Prm user data, the configuration from the Chk_Cfg the master sends (a
Get_Cfg reply while no Chk_Cfg was seen). When it knows a station's ident and configuration it looks
up the GSD (gsd/library.py: --gsd-dir / $PDRIVE_GSD_DIR first, then pdrive's own files) and cuts the
configuration into modules once (gsd/slavedata.py); from then on each Data_Exchange request (outputs)
and response (inputs) of that station is shown by module. The per-telegram cost is a dict lookup and
slicing: the GSD work happens when a Set_Prm, Chk_Cfg or Get_Cfg reply changes what is known, and its
result is cached per (ident, configuration, user data).

Sans-IO apart from reading GSD files: fdl frames in, the `decoded` object of docs/json.md out.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

from profidrive_cli import UsageError
from profidrive_cli.dp import services as S
from profidrive_cli.dp.cfg import CfgError
from profidrive_cli.fdl import frames as F
from profidrive_cli.gsd.slavedata import IN, OUT, SlaveLayout, layout

#: how many parameters that differ from the GSD's default the Chk_Cfg line names
SHOWN_PRM = 8


@dataclass
class _Seen:
    ident: int | None = None
    user_prm: bytes | None = None
    cfg: bytes | None = None
    cfg_is_chk: bool = False          # from a Chk_Cfg (else from a Get_Cfg reply)


class _Cuts:
    """One direction of a station, built once: the GSD file's name, its modules' (slot, name, start,
    end), the text's head -- and the pieces of the decoded object's text and JSON around each
    module's octets (ByModule), so that a Data_Exchange costs the octets' hex only."""
    __slots__ = ("file", "parts", "head", "reach", "text_pieces", "json_head", "json_mods",
                 "json_text_head", "json_text_pieces")

    def __init__(self, file: str, parts: tuple[tuple[int, str, int, int], ...], head: str):
        self.file, self.parts, self.head = file, parts, head
        #: an area longer than this holds every module (shorter: the modules that start in it)
        self.reach = max(a for _, _, a, _ in parts)
        self.text_pieces = tuple(f"{n} {name}: " for n, name, _, _ in parts)
        # json.dumps of {"gsd", "modules": [{"slot", "name", "offset", "octets"}], "text": [..]}:
        # JSON escapes character by character, so a text's escape is its pieces' escapes joined
        self.json_head = '{"gsd": ' + json.dumps(file) + ', "modules": ['
        self.json_mods = tuple(json.dumps({"slot": n, "name": name, "offset": a})[:-1] + ', "octets": "'
                               for n, name, a, _ in parts)
        self.json_text_head = '], "text": ["' + json.dumps(head)[1:-1]
        self.json_text_pieces = tuple(json.dumps(t)[1:-1] for t in self.text_pieces)


class DxView:
    """A Data_Exchange of a station whose modules are known, cut by module: its `decoded` object
    (docs/json.md: gsd, modules, text) as a dict (as_dict), as the text line (text) or as the text
    json.dumps gives for that dict (json_text), each made from pieces built once per station and
    the modules' octets in hex."""
    __slots__ = ("cuts", "which", "octets")

    def __init__(self, cuts: _Cuts, which: Sequence[int], octets: list[str]):
        self.cuts, self.which, self.octets = cuts, which, octets

    def text(self) -> str:
        pieces = self.cuts.text_pieces
        return self.cuts.head + "; ".join(pieces[i] + o for i, o in zip(self.which, self.octets))

    def as_dict(self) -> dict[str, Any]:
        parts = self.cuts.parts
        return {"gsd": self.cuts.file,
                "modules": [{"slot": parts[i][0], "name": parts[i][1], "offset": parts[i][2],
                             "octets": o} for i, o in zip(self.which, self.octets)],
                "text": [self.text()]}

    def json_text(self) -> str:
        """json.dumps(self.as_dict())."""
        cuts, octets, which = self.cuts, self.octets, self.which
        mods = ", ".join(cuts.json_mods[i] + o + '"}' for i, o in zip(which, octets))
        text = "; ".join(cuts.json_text_pieces[i] + o for i, o in zip(which, octets))
        return cuts.json_head + mods + cuts.json_text_head + text + '"]}'


class SlaveView:
    def __init__(self, gsd_dir: str | None = None, skip: Iterable[int] = ()):
        if gsd_dir is not None and not os.path.isdir(gsd_dir):   # exit 2 before listening
            why = "not a folder" if os.path.exists(gsd_dir) else "no such folder"
            raise UsageError(f"--gsd-dir {gsd_dir}: {why}")
        self.gsd_dir = gsd_dir
        self.skip = frozenset(skip)
        self._seen: dict[int, _Seen] = {}
        self._cuts: dict[tuple[int, str], _Cuts] = {}
        self._layouts: dict[tuple[int, bytes, bytes | None], SlaveLayout | None] = {}

    # -- per frame ------------------------------------------------------------------------------
    def dx_view(self, f: F.Frame) -> DxView | None:
        """A frame without SAPs: its area by module when it is a Data_Exchange of a station whose
        modules are known, else None."""
        if f.sd == F.SC or f.sd == F.SD4:
            return None
        if f.fc & F.FC_REQ:                                   # (f.is_request)
            if f.fc & 0x0F not in (F.SRD_LOW, F.SRD_HIGH):
                return None
            cuts = self._cuts.get((f.da, OUT))
        else:
            if not f.data:
                return None
            cuts = self._cuts.get((f.sa, IN))
        if cuts is None:
            return None
        data = f.data
        parts = cuts.parts
        which = range(len(parts)) if len(data) > cuts.reach else \
            [i for i, p in enumerate(parts) if p[2] < len(data)]
        return DxView(cuts, which, [data[parts[i][2]:parts[i][3]].hex(" ") for i in which])

    def decode(self, f: F.Frame, dec: dict[str, Any] | None) -> dict[str, Any] | None:
        """The frame's `decoded` object: `dec` (dp/du_decode.py's) with the GSD's view added, or a
        new one for a Data_Exchange of a station whose modules are known (dx_view)."""
        if f.dsap is None and f.ssap is None:
            v = self.dx_view(f)
            return dec if v is None else v.as_dict()
        if (f.is_request and f.dsap == S.SAP_SET_PRM and len(f.data) >= 7 and f.da not in self.skip
                and f.data[0] & 0xC0 != 0x40):             # not a release (Unlock_Req alone)
            st = self._seen.setdefault(f.da, _Seen())
            st.ident = int.from_bytes(f.data[4:6], "big")
            st.user_prm = bytes(f.data[7:])
            return self._learnt(f.da, dec)
        if f.is_request and f.dsap == S.SAP_CHK_CFG and f.da not in self.skip:
            st = self._seen.setdefault(f.da, _Seen())
            st.cfg, st.cfg_is_chk = bytes(f.data), True
            return self._learnt(f.da, dec, show=True)
        if not f.is_request and f.ssap == S.SAP_GET_CFG and f.data and f.sa not in self.skip:
            st = self._seen.setdefault(f.sa, _Seen())
            if not st.cfg_is_chk:
                st.cfg = bytes(f.data)
                return self._learnt(f.sa, dec, show=True)
        if (not f.is_request and f.ssap == S.SAP_SLAVE_DIAG and len(f.data) >= 6
                and f.sa not in self.skip):
            st = self._seen.setdefault(f.sa, _Seen())
            if st.ident is None:
                st.ident = int.from_bytes(f.data[4:6], "big")
                return self._learnt(f.sa, dec)
        return dec

    # -- when something changed -----------------------------------------------------------------
    def _learnt(self, address: int, dec: dict[str, Any] | None, show: bool = False) -> dict[str, Any] | None:
        st = self._seen[address]
        lay = self.layout_of(address)
        for d in (OUT, IN):
            self._cuts.pop((address, d), None)
        if lay is None:
            return dec
        name = (lay.gsd_path or "").replace("\\", "/").rsplit("/", 1)[-1]
        for d, label in ((OUT, "outputs"), (IN, "inputs")):
            parts = tuple((m.slot, m.short, m.out_offset if d == OUT else m.in_offset,
                           (m.out_offset + m.out_len) if d == OUT else (m.in_offset + m.in_len))
                          for m in lay.modules if (m.out_len if d == OUT else m.in_len))
            if parts:
                self._cuts[(address, d)] = _Cuts(name, parts, f"{label} by module ({name}): ")
        if not show:
            return dec
        out = dict(dec or {"text": []})
        out["text"] = list(out.get("text", []))
        out["gsd"] = name
        out["layout"] = [m.to_dict() for m in lay.modules]
        out["text"].append(f"by the GSD {name} (ident 0x{st.ident or 0:04X}, {lay.title}):")
        out["text"] += ["  " + line for line in lay.describe()]
        rows, warnings = lay.prm_rows()
        if rows:
            out["prm"] = rows
            odd = [r for r in rows if r["value"] != r["default"]]
            text = f"Set_Prm user data by the GSD: {len(rows)} parameters, {len(odd)} not the GSD's default"
            if odd:
                text += ": " + "; ".join(f"{r['name']} = {r['value']}" + (f" ({r['text'].strip()})"
                                         if r["text"] else "") for r in odd[:SHOWN_PRM])
                text += " ..." if len(odd) > SHOWN_PRM else ""
            out["text"].append(text)
        out["text"] += [f"Set_Prm: {w}" for w in warnings]
        return out

    def layout_of(self, address: int) -> SlaveLayout | None:
        """The station's modules as learnt so far (None: ident or configuration not seen, no GSD)."""
        st = self._seen.get(address)
        if st is None or st.ident is None or st.cfg is None:
            return None
        key = (st.ident, st.cfg, st.user_prm)
        if key not in self._layouts:
            from profidrive_cli.gsd.library import find_by_ident
            try:                    # a $PDRIVE_GSD_DIR that is not there: no GSD (a name is a label)
                g = find_by_ident(st.ident, self.gsd_dir)
                self._layouts[key] = None if g is None else layout(g, st.cfg, st.user_prm)
            except (CfgError, UsageError):
                self._layouts[key] = None
        return self._layouts[key]


__all__ = ["DxView", "SlaveView"]

