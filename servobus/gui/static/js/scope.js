// Scope panel: 1-8 channels of any axes, time base, trigger (auto/normal/single/roll,
// edge, level, pre-trigger), pause, cursors A/B with deltas, CSV and PNG export.
// Frames arrive binary (frames.js); the page acks each one once drawn, so the server
// never sends faster than this page draws.
import { parseFrame, FLAG_TRIGGERED, FLAG_HOLDING, FLAG_FREE_RUN } from "./frames.js";
import { api } from "./net.js";
import { $, axisLabel, el, fmt, download, fieldError, message, readField, signalUnit, unitsOf, COLORS } from "./util.js";

const WINDOWS = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20];
const MAX_CHANNELS = 8;
const OVERLAYS = 3;
const PLOT_HEIGHT = 380;

function windowLabel(s) { return s < 1 ? `${s * 1000} ms` : `${s} s`; }
function unitScale(unit) { return unit === "bit" ? "bit" : unit; }

export class ScopePanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.signals = ctx.info.signals;
    this.channels = [{ axis: ctx.selected, signal: "position" }, { axis: ctx.selected, signal: "speed" }];
    this.running = true;
    this.visible = false;
    this.plot = null;
    this.frame = null;
    this.data = null;
    this.cursorA = null;
    this.cursorB = null;
    this.pendingAck = null;
    this.draws = [];
    this.overlays = [];  // earlier triggered captures, newest first (drawn faded)
    this.lastTriggered = null;
    this.stats = { drawn: 0, fps: 0, frames: 0, lastSeq: 0, state: null };
    ctx.scope = this;

    const win = $("#scope-window");
    for (const w of WINDOWS) win.append(el("option", { value: w, text: windowLabel(w), selected: w === 2 }));
    for (const id of ["#scope-window", "#trig-mode", "#trig-source", "#trig-edge", "#trig-level", "#trig-pre"]) {
      $(id).addEventListener("change", () => this.configure());
    }
    $("#trig-source").addEventListener("change", () => this.renderTriggerUnit());
    $("#scope-add").addEventListener("click", () => {
      if (this.channels.length >= MAX_CHANNELS) return;
      this.channels.push({ axis: this.ctx.selected, signal: "current" });
      this.renderChannels();
      this.configure();
    });
    $("#trig-overlay").addEventListener("change", (ev) => { if (!ev.target.checked) this.overlays = []; this.redraw(); });
    $("#scope-run").addEventListener("click", () => this.setRunning(!this.running));
    $("#scope-arm").addEventListener("click", () => ctx.link.send({ type: "scope_arm" }));
    $("#scope-csv").addEventListener("click", () => ctx.link.send({ type: "scope_csv" }));
    $("#scope-png").addEventListener("click", () => this.png());
    $("#scope-clear-cursors").addEventListener("click", () => { this.cursorA = this.cursorB = null; this.redraw(); });
    ctx.link.binary = (buf) => this.onFrame(buf);
    ctx.link.on("scope_state", (doc) => { this.stats.state = doc; this.renderStatus(); });
    ctx.link.on("csv", (doc) => download(`servobus-scope-${new Date().toISOString().replace(/[:.]/g, "-")}.csv`,
      new Blob([doc.text], { type: "text/csv" })));
    ctx.link.on("hello", () => { if (this.visible) this.configure(); });
    ctx.link.on("error", (doc) => { if (doc.request && doc.request.startsWith("scope")) $("#scope-status").textContent = `scope: ${doc.message}`; });
    window.addEventListener("resize", () => { if (this.visible) { this.build(); this.configure(); } });
    ctx.onSelect((id) => {
      $("#scope-jog-axis").textContent = `${axisLabel(ctx.identity(id))}, speed from Motion`;
      $("#scope-move-unit").textContent = unitsOf(ctx.identity(id)).position;
      this.follow(id);
    });
    $("#scope-move-plus").addEventListener("click", () => this.move(1));
    $("#scope-move-minus").addEventListener("click", () => this.move(-1));
    ctx.onIdentity(() => { this.renderChannels(); if (this.visible) this.build(); });
    this.renderChannels();
  }

  // Leaving the tab keeps what the scope caught (issue 33): a trigger (auto, normal,
  // single) stays armed, so a move started from another tab is caught, and only triggered
  // captures are kept meanwhile; a rolling scope pauses (no frames nobody sees). Coming
  // back shows the last capture (auto: paused on it, Run goes on) and sends only settings
  // that changed.
  show() {
    this.visible = true;
    this.build();
    if (this.data && this.data.length === this.channels.length + 1) this.plot.setData(this.data);
    if (JSON.stringify(this.settings()) !== this.sent) this.configure();
    else if (this.caughtAway && $("#trig-mode").value === "auto" && this.running) this.setRunning(false);
    else if (this.pausedHidden && this.running) this.ctx.link.send({ type: "scope_run", running: true });
    this.pausedHidden = this.caughtAway = false;
  }
  hide() {
    this.visible = false;
    this.caughtAway = false;
    this.pausedHidden = $("#trig-mode").value === "roll";
    if (this.pausedHidden) this.ctx.link.send({ type: "scope_run", running: false });
  }

  // Channels not pinned follow the axis selected on the page (issue 33); choosing a
  // channel's axis pins it.
  follow(id) {
    let changed = false;
    for (const ch of this.channels) if (!ch.pinned && ch.axis !== id) { ch.axis = id; changed = true; }
    if (!changed) return;
    this.renderChannels();
    if (this.visible) this.build();
    // hidden: an armed scope takes the new channels at once, to catch the next move
    if (this.visible || (this.sent && $("#trig-mode").value !== "roll")) this.configure(true);
    else this.sent = null;
  }

  // A relative move of the selected axis from here, to watch it (issue 33).
  async move(sign) {
    const field = $("#scope-move-value");
    const value = readField(field);
    const msg = $("#scope-msg");
    if (value === null) { message(msg, "move: not sent - correct the marked field", "error"); return; }
    const id = this.ctx.selected;
    const unit = unitsOf(this.ctx.identity(id)).position;
    try {
      await api(`/api/axes/${id}/move`, { value: sign * value, unit, relative: true });
      message(msg, `move by ${sign * value} ${unit}: sent to ${axisLabel(this.ctx.identity(id))}`, "ok");
    } catch (err) {
      message(msg, `move: ${err.message}`, "error");
      if (err.status === 400) fieldError(field, err.message);
    }
  }

  signal(name) { return this.signals.find((s) => s.name === name); }

  // A channel's unit as the server sends it (the axis's own: mm, mm/s, deg ...; issue 33).
  unitOf(ch) { return signalUnit(this.ctx.identity(ch.axis), this.signal(ch.signal)); }

  // "x position [mm]": how a channel is named in legends, cursors and exports.
  channelName(ch) { return `${axisLabel(this.ctx.identity(ch.axis))} ${this.signal(ch.signal).label} [${this.unitOf(ch)}]`; }

  renderChannels() {
    const box = $("#scope-channels");
    box.replaceChildren(...this.channels.map((ch, i) => {
      const axisSel = el("select", { "data-ch": i, "data-field": "axis" },
        ...this.ctx.info.axes.map((a) => el("option", { value: a.id, text: axisLabel(a), title: `${a.protocol} · ${a.family_title}`, selected: a.id === ch.axis })));
      const sigSel = el("select", { "data-ch": i, "data-field": "signal" },
        ...this.signals.map((s) => el("option", { value: s.name, text: `${s.label} [${signalUnit(this.ctx.identity(ch.axis), s)}]`, selected: s.name === ch.signal })));
      axisSel.addEventListener("change", () => { ch.axis = Number(axisSel.value); ch.pinned = true; this.channelsChanged(); });
      sigSel.addEventListener("change", () => { ch.signal = sigSel.value; this.channelsChanged(); });
      const remove = el("button", { text: "×", title: "remove channel", onclick: () => {
        if (this.channels.length > 1) { this.channels.splice(i, 1); this.channelsChanged(); }
      } });
      remove.disabled = this.channels.length === 1;
      const pin = el("button", { class: `pin${ch.pinned ? " on" : ""}`, "aria-pressed": ch.pinned ? "true" : "false",
        text: ch.pinned ? "pinned" : "follows",
        title: ch.pinned ? "pinned to its axis: click to follow the selected axis" : "follows the selected axis: click to pin it",
        onclick: () => { ch.pinned = !ch.pinned; if (!ch.pinned) ch.axis = this.ctx.selected; this.channelsChanged(); } });
      return el("div", { class: "chan" }, el("span", { class: "swatch", style: `background:${COLORS[i]}` }), axisSel, sigSel, pin, remove);
    }));
    $("#scope-add").disabled = this.channels.length >= MAX_CHANNELS;
    const src = $("#trig-source");
    const keep = Math.min(Number(src.value || 0), this.channels.length - 1);
    src.replaceChildren(...this.channels.map((ch, i) =>
      el("option", { value: i, text: `${i + 1}: ${axisLabel(this.ctx.identity(ch.axis))} ${this.signal(ch.signal).label}`, selected: i === keep })));
    this.renderTriggerUnit();
  }

  renderTriggerUnit() {
    const ch = this.channels[Number($("#trig-source").value || 0)];
    $("#trig-unit").textContent = ch ? this.unitOf(ch) : "";
  }

  channelsChanged() { this.renderChannels(); this.build(); this.configure(); }

  settings() {
    return {
      channels: this.channels.map((c) => ({ axis: c.axis, signal: c.signal })),
      window_s: Number($("#scope-window").value), mode: $("#trig-mode").value,
      edge: $("#trig-edge").value, level: this.fieldValue("#trig-level", 0),
      pre: this.fieldValue("#trig-pre", 10) / 100,
      trigger_channel: Number($("#trig-source").value || 0),
      width: this.plotWidth(),
    };
  }

  // A trigger field's number; a refused text shows at the field and the last good value
  // (else ``fallback``) stays in use, so nothing made up is sent.
  fieldValue(sel, fallback) {
    this.good = this.good || {};
    const v = readField($(sel));
    if (v !== null) this.good[sel] = v;
    return this.good[sel] ?? fallback;
  }

  // The plot's width in pixels (the last one seen while the tab showed, when hidden).
  plotWidth() {
    const w = $("#scope-plot").clientWidth;
    if (w) this.lastWidth = Math.round(w);
    return this.lastWidth || 1000;
  }

  // ``hidden``: sent while another tab shows (follow) - the plot is built on return.
  configure(hidden = false) {
    if (!this.visible && !hidden) return;
    this.frame = null;
    this.overlays = [];
    this.lastTriggered = null;
    this.pendingAck = null;
    const settings = this.settings();
    this.sent = JSON.stringify(settings);
    this.ctx.link.send({ type: "scope", settings });
    if (!this.running) this.ctx.link.send({ type: "scope_run", running: false });
  }

  setRunning(running) {
    this.running = running;
    $("#scope-run").textContent = running ? "Pause" : "Run";
    this.ctx.link.send({ type: "scope_run", running });
  }

  // ------------------------------------------------------------------ plot
  build() {
    const host = $("#scope-plot");
    if (this.plot) { this.plot.destroy(); this.plot = null; }
    const bits = this.channels.filter((c) => this.unitOf(c) === "bit");
    this.bitSlot = new Map();
    bits.forEach((c, k) => this.bitSlot.set(c, k));
    const scales = { x: { time: false, range: () => this.xRange() } };
    const axes = [{ stroke: "#8994a3", grid: { stroke: "#262c35" }, ticks: { stroke: "#323a46" }, space: 70,
      values: (u, vals) => { const span = u.scales.x.max - u.scales.x.min; return vals.map((v) => fmtTick(v, span)); } }];
    const units = [];
    for (const c of this.channels) {
      const unit = unitScale(this.unitOf(c));
      if (!units.includes(unit)) units.push(unit);
    }
    units.forEach((unit, i) => {
      scales[unit] = unit === "bit" ? { range: [-0.3, Math.max(1, bits.length) * 1.25] }
        : { range: (u, lo, hi) => padRange(lo, hi) };
      axes.push({ scale: unit, side: i === 0 ? 3 : 1, stroke: "#8994a3", label: unit,
        grid: { show: i === 0, stroke: "#262c35" }, ticks: { stroke: "#323a46" },
        values: unit === "bit" ? (u, vals) => vals.map(() => "") : (u, vals) => vals.map((v) => fmt(v)),
        size: 64 });
    });
    const series = [{ label: "t", value: (u, v) => (v === null || v === undefined ? "–" : fmtTime(v)) },
      ...this.channels.map((c, i) => {
        return { label: `${i + 1}: ${this.channelName(c)}`, stroke: COLORS[i], width: 1.25,
          scale: unitScale(this.unitOf(c)), points: { show: false },
          value: (u, v, si, idx) => fmt(this.rawValue(si - 1, idx)) };
      })];
    const width = Math.max(300, host.clientWidth || 900);
    this.plot = new uPlot({
      width, height: PLOT_HEIGHT, scales, axes, series,
      legend: { live: true }, cursor: { drag: { x: false, y: false }, points: { show: false } },
      hooks: { draw: [(u) => this.onDraw(u)] },
    }, [[], ...this.channels.map(() => [])], host);
    this.plot.over.addEventListener("mouseup", (ev) => this.placeCursor(ev));
    this.renderCursors();
  }

  xRange() {
    const f = this.frame;
    if (!f || f.n === 0) return [-Number($("#scope-window").value || 1), 0];
    return [f.x[0], f.x[f.n - 1]];
  }

  onFrame(buf) {
    const f = parseFrame(buf);
    if (!this.running) {  // paused: the picture holds (a frame on its way is only acked)
      this.ctx.link.send({ type: "ack", seq: f.seq });
      return;
    }
    if (!this.visible) {  // another tab: acked at once; a triggered capture is kept
      this.ctx.link.send({ type: "ack", seq: f.seq });
      if (!(f.flags & FLAG_TRIGGERED) || !this.plot || f.ys.length !== this.channels.length) return;
      this.caughtAway = true;
    }
    if (!this.plot || f.ys.length !== this.channels.length) {  // from before a change: drop,
      this.ctx.link.send({ type: "ack", seq: f.seq });          // but never hold the server up
      return;
    }
    if (f.flags & FLAG_TRIGGERED) {
      if (this.lastTriggered && $("#trig-overlay").checked) {
        this.overlays.unshift(this.lastTriggered);
        this.overlays.length = Math.min(this.overlays.length, OVERLAYS);
      }
      this.lastTriggered = f;
    }
    this.frame = f;
    this.stats.frames++;
    this.stats.lastSeq = f.seq;
    const data = [f.x];
    f.ys.forEach((y, i) => data.push(this.display(i, y)));
    this.data = data;
    if (!this.visible) return;  // kept for when the tab shows again
    this.pendingAck = f.seq;
    this.setDataAt = performance.now();
    this.plot.setData(data);
  }

  // What is drawn: bits stacked (slot k at k*1.25), NaN -> null (a gap, not a poisoned range).
  display(i, y) {
    const ch = this.channels[i];
    const slot = this.bitSlot.get(ch);
    let hasNaN = false;
    for (let k = 0; k < y.length; k++) if (y[k] !== y[k]) { hasNaN = true; break; }
    if (slot === undefined && !hasNaN) return y;
    const out = new Array(y.length);
    for (let k = 0; k < y.length; k++) {
      const v = y[k];
      out[k] = v !== v ? null : slot === undefined ? v : v + slot * 1.25;
    }
    return out;
  }

  rawValue(ch, idx) {
    const f = this.frame;
    if (!f || idx === null || idx === undefined || idx >= f.n) return null;
    const v = f.ys[ch][idx];
    return v !== v ? null : v;
  }

  onDraw(u) {
    const now = performance.now();
    if (this.setDataAt) { this.stats.drawMs = now - this.setDataAt; this.setDataAt = 0; }
    this.stats.drawn++;
    this.draws.push(now);
    while (this.draws.length && this.draws[0] < now - 1000) this.draws.shift();
    this.stats.fps = this.draws.length;
    if (this.pendingAck !== null) {
      this.ctx.link.send({ type: "ack", seq: this.pendingAck });
      this.pendingAck = null;
    }
    const ctx = u.ctx;
    const f = this.frame;
    const { left, top, width, height } = u.bbox;
    ctx.save();
    ctx.lineWidth = devicePixelRatio;
    if (f && (f.flags & FLAG_TRIGGERED)) {  // trigger time and level
      const x = u.valToPos(0, "x", true);
      ctx.strokeStyle = "#f0b429";
      ctx.setLineDash([4 * devicePixelRatio, 4 * devicePixelRatio]);
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
      const tc = this.channels[Number($("#trig-source").value || 0)];
      if (tc) {
        const scale = unitScale(this.unitOf(tc));
        const slot = this.bitSlot.get(tc);
        const level = ((this.good || {})["#trig-level"] ?? 0) + (slot === undefined ? 0 : slot * 1.25);
        const y = u.valToPos(level, scale, true);
        if (y >= top && y <= top + height) { ctx.beginPath(); ctx.moveTo(left, y); ctx.lineTo(left + width, y); ctx.stroke(); }
      }
    }
    ctx.setLineDash([]);
    if ($("#trig-overlay").checked && f && (f.flags & FLAG_TRIGGERED)) this.drawOverlays(u);
    for (const [name, t, color] of [["A", this.cursorA, "#ffffff"], ["B", this.cursorB, "#ff6b9a"]]) {
      if (t === null) continue;
      const x = u.valToPos(t, "x", true);
      if (x < left || x > left + width) continue;
      ctx.strokeStyle = color; ctx.fillStyle = color;
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
      ctx.font = `${12 * devicePixelRatio}px sans-serif`;
      ctx.fillText(name, x + 4 * devicePixelRatio, top + 14 * devicePixelRatio);
    }
    ctx.restore();
  }

  // Earlier captures, faded (newest strongest), on the same scales as the live channels.
  drawOverlays(u) {
    const ctx = u.ctx;
    const { left, top, width, height } = u.bbox;
    ctx.save();
    ctx.beginPath(); ctx.rect(left, top, width, height); ctx.clip();
    ctx.lineWidth = devicePixelRatio;
    this.overlays.forEach((o, age) => {
      ctx.globalAlpha = 0.45 - 0.12 * age;
      this.channels.forEach((ch, i) => {
        if (i >= o.ys.length) return;
        const scale = unitScale(this.unitOf(ch));
        const slot = this.bitSlot.get(ch);
        const shift = slot === undefined ? 0 : slot * 1.25;
        const y = o.ys[i];
        ctx.strokeStyle = COLORS[i];
        ctx.beginPath();
        let pen = false;
        for (let k = 0; k < o.n; k++) {
          const v = y[k];
          if (v !== v) { pen = false; continue; }
          const px = u.valToPos(o.x[k], "x", true), py = u.valToPos(v + shift, scale, true);
          if (pen) ctx.lineTo(px, py); else { ctx.moveTo(px, py); pen = true; }
        }
        ctx.stroke();
      });
    });
    ctx.restore();
  }

  redraw() { if (this.plot) this.plot.redraw(false, false); this.renderCursors(); }

  placeCursor(ev) {
    const u = this.plot;
    if (!u || u.cursor.left === undefined || u.cursor.left < 0) return;
    const t = u.posToVal(u.cursor.left, "x");
    if (ev.shiftKey) this.cursorB = t; else this.cursorA = t;
    this.redraw();
  }

  valueAt(ch, t) {
    const f = this.frame;
    if (!f || f.n === 0 || t === null) return null;
    let lo = 0, hi = f.n - 1;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (f.x[mid] < t) lo = mid + 1; else hi = mid; }
    if (lo > 0 && Math.abs(f.x[lo - 1] - t) < Math.abs(f.x[lo] - t)) lo--;
    return this.rawValue(ch, lo);
  }

  renderCursors() {
    const table = $("#scope-cursors");
    const { cursorA: a, cursorB: b } = this;
    if (a === null && b === null) { table.replaceChildren(); return; }
    const dt = a !== null && b !== null ? b - a : null;
    const rows = [el("tr", {}, el("th", { text: "" }), el("th", { class: "num", text: "A" }),
      el("th", { class: "num", text: "B" }), el("th", { class: "num", text: "B − A" })),
    el("tr", {}, el("td", { text: "time" }), el("td", { class: "num", text: fmtTime(a) }),
      el("td", { class: "num", text: fmtTime(b) }),
      el("td", { class: "num", text: dt === null ? "–" : `${fmtTime(dt)}  (1/Δt ${dt ? fmt(1 / Math.abs(dt)) : "–"} Hz)` }))];
    this.channels.forEach((c, i) => {
      const va = this.valueAt(i, a), vb = this.valueAt(i, b);
      rows.push(el("tr", {}, el("td", {}, el("span", { class: "swatch", style: `display:inline-block;width:10px;height:10px;background:${COLORS[i]};margin-right:6px` }),
        this.channelName(c)),
      el("td", { class: "num", text: fmt(va) }), el("td", { class: "num", text: fmt(vb) }),
      el("td", { class: "num", text: va !== null && vb !== null ? fmt(vb - va) : "–" })));
    });
    table.replaceChildren(...rows);
  }

  renderStatus() {
    const s = this.stats.state;
    const f = this.frame;
    if (!s) return;
    let state;
    if (!s.running) state = "paused";
    else if (s.holding) state = "single: captured (Arm for the next)";
    else if (s.mode === "roll") state = "rolling";
    else if (f && (f.flags & FLAG_FREE_RUN)) state = "auto: no trigger, free-running";
    else if (f && (f.flags & FLAG_TRIGGERED)) state = `${s.mode}: triggered`;
    else state = `${s.mode}: waiting for trigger`;
    const sources = s.sources || [];
    const src = sources.filter((x) => x.running || !x.error).map((x) => {
      const kind = x.source === "trace" ? "drive trace" : x.source === "poll" ? "polled" : "starting";
      return `${axisLabel(this.ctx.identity(x.axis))} ${kind} ${fmt(x.rate_hz)} Hz${x.error ? ` (${x.error})` : ""}`;
    }).join(", ");
    // a sampler that stopped says why, in the status line, in the error colour (never silent)
    const stopped = sources.filter((x) => !x.running && x.error)
      .map((x) => el("span", { class: "sampler-error", text: ` · ${axisLabel(this.ctx.identity(x.axis))} ${x.error}` }));
    const lat = s.latency_ms ? `delay ${s.latency_ms.median.toFixed(0)} ms (p95 ${s.latency_ms.p95.toFixed(0)})` : "";
    $("#scope-status").replaceChildren(el("span", { class: "state", text: state }), ...stopped,
      `${src ? " · " + src : ""} · ${f ? `${f.raw.toLocaleString("en-US")} samples in view` : "no data yet"} · ${this.stats.fps} frames/s drawn ${lat ? "· " + lat : ""}`);
    if (this.cursorA !== null || this.cursorB !== null) this.renderCursors();
  }

  png() {
    if (!this.plot) return;
    const src = this.plot.ctx.canvas;
    const pad = 28 * devicePixelRatio;
    const out = document.createElement("canvas");
    out.width = src.width; out.height = src.height + pad;
    const c = out.getContext("2d");
    c.fillStyle = "#0d0f12"; c.fillRect(0, 0, out.width, out.height);
    c.drawImage(src, 0, pad);
    c.font = `${12 * devicePixelRatio}px sans-serif`;
    let x = 8 * devicePixelRatio;
    this.channels.forEach((ch, i) => {
      const text = `${i + 1}: ${this.channelName(ch)}`;
      c.fillStyle = COLORS[i]; c.fillText(text, x, 18 * devicePixelRatio);
      x += c.measureText(text).width + 16 * devicePixelRatio;
    });
    out.toBlob((blob) => download(`servobus-scope-${new Date().toISOString().replace(/[:.]/g, "-")}.png`, blob));
  }
}

function fmtTick(v, span) {
  if (span >= 1.5) return `${+v.toFixed(2)} s`;
  if (span >= 0.2) return `${+(v * 1000).toFixed(0)} ms`;
  return `${+(v * 1000).toFixed(span >= 0.02 ? 1 : 2)} ms`;
}

function fmtTime(v) {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  const a = Math.abs(v);
  if (a === 0) return "0";
  if (a < 1) return `${(v * 1000).toFixed(a < 0.01 ? 2 : 1)} ms`;
  return `${v.toFixed(3)} s`;
}

function padRange(lo, hi) {
  if (lo === null || hi === null || !Number.isFinite(lo) || !Number.isFinite(hi)) return [-1, 1];
  if (lo === hi) { const d = Math.abs(lo) * 0.05 || 1; return [lo - d, hi + d]; }
  const d = (hi - lo) * 0.08;
  return [lo - d, hi + d];
}

export { FLAG_HOLDING };
