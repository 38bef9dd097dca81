// pdrive monitor's page: polls /api/live every 2 s and fills the station table, the bus figures,
// the likely causes and the events; draws the trends (SVG, no library) from /api/trend.
// The token of the page's own address (?token=...) goes on every fetch (Authorization: Bearer)
// and on every capture link (?token=). No external resource; text is set as text, never as HTML.
"use strict";
(function () {
  const LIVE_EVERY_MS = 2000;
  const TREND_EVERY_MS = 60000;
  const BUS_SERIES = ["frames", "tokens", "errors", "load_percent", "rotation_s"];
  const STATION_SERIES = ["exchanges", "retries", "no_answer", "illegal", "reparams"];
  const token = new URLSearchParams(window.location.search).get("token");
  let selected = null;          // the station whose trends are shown
  let noHistory = false;        // /api/trend answered 404: the monitor keeps no history

  function $(sel) { return document.querySelector(sel); }

  function el(tag, attrs, text) {
    const e = document.createElement(tag);
    for (const k in (attrs || {})) { e.setAttribute(k, attrs[k]); }
    if (text !== undefined && text !== null) { e.textContent = String(text); }
    return e;
  }

  function svg(tag, attrs) {
    const e = document.createElementNS("http://www.w3.org/2000/svg", tag);
    for (const k in (attrs || {})) { e.setAttribute(k, attrs[k]); }
    return e;
  }

  function withToken(url) {
    if (!token) { return url; }
    return url + (url.indexOf("?") < 0 ? "?" : "&") + "token=" + encodeURIComponent(token);
  }

  function getJSON(url) {
    const headers = token ? { "Authorization": "Bearer " + token } : {};
    return fetch(url, { headers: headers, cache: "no-store", credentials: "omit" })
      .then(function (r) {
        return r.json().catch(function () { return {}; }).then(function (body) {
          if (!r.ok) {
            const err = new Error((body && body.error) || ("HTTP " + r.status));
            err.status = r.status;
            throw err;
          }
          return body;
        });
      });
  }

  function pad(n) { return (n < 10 ? "0" : "") + n; }

  function when(t) {
    if (t === null || t === undefined) { return ""; }
    const d = new Date(t * 1000);
    return d.getFullYear() + "-" + pad(d.getMonth() + 1) + "-" + pad(d.getDate()) + " " +
      pad(d.getHours()) + ":" + pad(d.getMinutes()) + ":" + pad(d.getSeconds());
  }

  function seconds(s) {
    if (s === null || s === undefined) { return ""; }
    return s < 1 ? (s * 1000).toFixed(1) + " ms" : s.toFixed(2) + " s";
  }

  function showError(text) {
    const e = $("#error");
    if (text) { e.textContent = text; e.hidden = false; } else { e.textContent = ""; e.hidden = true; }
  }

  function renderStatus(v) {
    const parts = ["port " + (v.port || "?")];
    if (v.baud) { parts.push(v.baud + " bit/s"); }
    parts.push("as of " + when(v.t));
    if (v.started) { parts.push("since " + when(v.started)); }
    if (v.store) {
      parts.push("history " + (v.store.bytes / 1e6).toFixed(1) + " of " +
        (v.store.max_bytes / 1e6).toFixed(0) + " MB" + (v.store.full ? " (disk full)" : ""));
    } else {
      parts.push("no history");
    }
    $("#status").textContent = parts.join(" \u00b7 ");
    const a = $("#adapter");
    a.textContent = v.adapter === "lost" ? "adapter lost, reopening" : "";
    a.className = v.adapter === "lost" ? "lost" : "";
  }

  function renderStations(stations) {
    const body = $("#stations tbody");
    body.replaceChildren();
    (stations || []).forEach(function (s) {
      const tr = el("tr", { "data-station": String(s.station) });
      tr.className = "state-" + (s.colour || "grey") + (s.station === selected ? " selected" : "");
      const c = s.counters || {};
      tr.appendChild(el("td", { "class": "num" }, s.station));
      const st = el("td");
      st.appendChild(el("span", { "class": "state" }, s.state));
      tr.appendChild(st);
      tr.appendChild(el("td", {}, s.ident_hex || ""));
      tr.appendChild(el("td", {}, s.profile || ""));
      tr.appendChild(el("td", {}, s.drive_state || ""));
      tr.appendChild(el("td", { "class": s.fault ? "fault-yes" : "" },
        s.fault === null || s.fault === undefined ? "" : (s.fault ? "FAULT" : "no")));
      STATION_SERIES.forEach(function (k) {
        tr.appendChild(el("td", { "class": "num" }, c[k] === undefined ? "" : c[k]));
      });
      tr.appendChild(el("td", { "class": "num" }, seconds(s.cycle_s)));
      tr.appendChild(el("td", {}, when(s.last_seen)));
      tr.addEventListener("click", function () { select(s.station); });
      body.appendChild(tr);
    });
  }

  function renderBus(bus) {
    const dl = $("#bus");
    dl.replaceChildren();
    bus = bus || {};
    const errs = bus.errors || {};
    const errText = Object.keys(errs).map(function (k) { return k + " " + errs[k]; }).join(", ");
    [["Frames", bus.frames], ["Tokens", bus.tokens],
     ["Masters", (bus.masters || []).join(", ") || "none heard"],
     ["Bus load", bus.load_percent === null || bus.load_percent === undefined ? "" :
       bus.load_percent.toFixed(1) + " %"],
     ["Token rotation", seconds(bus.rotation_s)], ["Cycle", seconds(bus.cycle_s)],
     ["Errors", errText || "none"]].forEach(function (row) {
      dl.appendChild(el("dt", {}, row[0]));
      dl.appendChild(el("dd", {}, row[1] === undefined ? "" : row[1]));
    });
  }

  function renderCauses(causes) {
    const ul = $("#causes");
    ul.replaceChildren();
    if (!causes || !causes.length) { ul.appendChild(el("li", { "class": "none" }, "none")); return; }
    causes.forEach(function (c) {
      const li = el("li", { "class": "cause" });
      li.appendChild(el("strong", {}, c.title));
      li.appendChild(el("span", { "class": "score" },
        "score " + Number(c.score).toFixed(2) +
        (c.stations && c.stations.length ? " \u00b7 station " + c.stations.join(", ") : "")));
      const ev = el("ul", { "class": "evidence" });
      (c.evidence || []).forEach(function (e) { ev.appendChild(el("li", {}, e)); });
      li.appendChild(ev);
      ul.appendChild(li);
    });
  }

  function renderEvents(events) {
    const body = $("#events tbody");
    body.replaceChildren();
    (events || []).forEach(function (e) {
      const tr = el("tr", { "class": "kind-" + e.kind });
      tr.appendChild(el("td", {}, when(e.t)));
      tr.appendChild(el("td", { "class": "num" }, e.station === null ? "" : e.station));
      tr.appendChild(el("td", { "class": "kind" }, e.kind));
      tr.appendChild(el("td", { "class": "text" },
        e.text + (e.repeats ? " (\u00d7" + (e.repeats + 1) + ")" : "")));
      const cause = el("td", { "class": "cause" }, e.cause || "");
      if (e.evidence && e.evidence.length) { cause.title = e.evidence.join("\n"); }
      tr.appendChild(cause);
      const cap = el("td");
      if (e.capture && e.capture_present !== false) {
        const a = el("a", { "class": "capture", "download": e.capture,
          "href": withToken("captures/" + encodeURIComponent(e.capture)) }, "pcap");
        cap.appendChild(a);
      }
      tr.appendChild(cap);
      body.appendChild(tr);
    });
  }

  function pollLive() {
    getJSON("api/live").then(function (v) {
      showError("");
      renderStatus(v);
      renderStations(v.stations);
      renderBus(v.bus);
      renderCauses(v.causes);
      renderEvents(v.events);
      if (selected === null && v.stations && v.stations.length) {
        select(v.stations[0].station);
      }
    }).catch(function (err) {
      showError("the monitor does not answer: " + err.message);
    }).finally(function () {
      window.setTimeout(pollLive, LIVE_EVERY_MS);
    });
  }

  // one small SVG plot per series: the values per bucket, a gap where a bucket has none
  function plot(title, t, values) {
    const W = 300, H = 90, L = 40, R = 6, T = 6, B = 16;
    const box = el("div", { "class": "plot" });
    const nums = values.filter(function (v) { return v !== null && v !== undefined; });
    const max = nums.length ? Math.max.apply(null, nums) : 0;
    const last = nums.length ? nums[nums.length - 1] : null;
    box.appendChild(el("div", { "class": "title" }, title + "  (max " + fmt(max) + ")"));
    const s = svg("svg", { "width": W, "height": H, "viewBox": "0 0 " + W + " " + H });
    s.appendChild(svg("line", { "class": "axis", "x1": L, "y1": H - B, "x2": W - R, "y2": H - B }));
    s.appendChild(svg("line", { "class": "axis", "x1": L, "y1": T, "x2": L, "y2": H - B }));
    const top = svg("text", { "x": L - 3, "y": T + 8, "text-anchor": "end" });
    top.textContent = fmt(max);
    s.appendChild(top);
    const zero = svg("text", { "x": L - 3, "y": H - B, "text-anchor": "end" });
    zero.textContent = "0";
    s.appendChild(zero);
    if (t.length) {
      const t0 = t[0], t1 = t[t.length - 1] > t0 ? t[t.length - 1] : t0 + 1;
      const left = svg("text", { "x": L, "y": H - 3 });
      left.textContent = when(t0).slice(5, 16);
      s.appendChild(left);
      const right = svg("text", { "x": W - R, "y": H - 3, "text-anchor": "end" });
      right.textContent = when(t[t.length - 1]).slice(5, 16);
      s.appendChild(right);
      let pts = [];
      const flush = function () {
        if (pts.length === 1) { pts.push(pts[0]); }
        if (pts.length) { s.appendChild(svg("polyline", { "points": pts.join(" ") })); }
        pts = [];
      };
      for (let i = 0; i < t.length; i++) {
        const v = values[i];
        if (v === null || v === undefined) { flush(); continue; }
        const x = L + (W - L - R) * (t[i] - t0) / (t1 - t0);
        const y = (H - B) - (H - B - T) * (max > 0 ? v / max : 0);
        pts.push(x.toFixed(1) + "," + y.toFixed(1));
      }
      flush();
    }
    box.appendChild(s);
    box.dataset.last = last === null ? "" : String(last);
    return box;
  }

  function fmt(v) {
    if (v === null || v === undefined) { return ""; }
    if (Math.abs(v) >= 1e6) { return (v / 1e6).toFixed(1) + "M"; }
    if (Math.abs(v) >= 1e3) { return (v / 1e3).toFixed(1) + "k"; }
    return Number.isInteger(v) ? String(v) : v.toPrecision(3);
  }

  function drawTrend(target, trend, names) {
    const box = $(target);
    box.replaceChildren();
    const series = trend.series || {};
    names.concat(Object.keys(series).filter(function (k) { return names.indexOf(k) < 0; }))
      .forEach(function (name) {
        if (series[name]) { box.appendChild(plot(name, trend.t || [], series[name])); }
      });
  }

  function loadTrends() {
    if (noHistory) { return; }
    const hours = $("#range").value;
    getJSON("api/trend?station=bus&hours=" + hours).then(function (tr) {
      $("#trend-note").textContent = "";
      drawTrend("#trend-bus", tr, BUS_SERIES);
    }).catch(function (err) {
      if (err.status === 404) {
        noHistory = true;
        $("#trend-note").textContent = "No trends: this monitor keeps no history (--db).";
      } else {
        $("#trend-note").textContent = "trends: " + err.message;
      }
    });
    if (selected !== null) {
      const st = selected;
      getJSON("api/trend?station=" + st + "&hours=" + hours).then(function (tr) {
        if (st !== selected) { return; }
        $("#trend-station-title").textContent = "Station " + st;
        drawTrend("#trend-station", tr, STATION_SERIES);
      }).catch(function () { /* said by the bus trend's note */ });
    }
  }

  function select(station) {
    selected = station;
    document.querySelectorAll("#stations tbody tr").forEach(function (tr) {
      tr.classList.toggle("selected", tr.getAttribute("data-station") === String(station));
    });
    loadTrends();
  }

  $("#range").addEventListener("change", loadTrends);
  pollLive();
  window.setInterval(loadTrends, TREND_EVERY_MS);
})();
