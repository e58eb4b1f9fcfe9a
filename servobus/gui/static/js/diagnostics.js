// Diagnostics panel: alarm log, link statistics, decoded traffic (what `servobus sniff` shows).
import { api } from "./net.js";
import { $, axisLabel, el, fmt } from "./util.js";

const POLL_MS = 500;
const KEEP_LINES = 1500;
// A request alone, a reply alone, or one transaction (the server joins them: issue 33).
const ARROWS = { tx: "→", rx: "←", pair: "⇄" };

export class DiagnosticsPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.timer = null;
    this.after = 0;
    this.lines = [];
    this.paused = false;
    $("#traffic-pause").addEventListener("click", () => {
      this.paused = !this.paused;
      $("#traffic-pause").textContent = this.paused ? "Resume" : "Pause";
    });
    $("#traffic-clear").addEventListener("click", () => { this.lines = []; this.renderTraffic(); });
    $("#traffic-filter").addEventListener("input", () => this.renderTraffic());
  }
  show() { this.poll(); this.timer = setInterval(() => this.poll(), POLL_MS); }
  hide() { clearInterval(this.timer); this.timer = null; }

  async poll() {
    let doc;
    try { doc = await api(`/api/diagnostics?after=${this.after}`); } catch (err) {
      $("#link-extra").textContent = `diagnostics: ${err.message}`;
      return;
    }
    this.renderAlarms(doc.alarms);
    this.renderLinks(doc);
    if (!this.paused && doc.traffic.length) {
      this.after = doc.traffic[doc.traffic.length - 1].seq;
      this.lines.push(...doc.traffic);
      if (this.lines.length > KEEP_LINES) this.lines.splice(0, this.lines.length - KEEP_LINES);
      this.renderTraffic();
    }
    const c = doc.traffic_counts;
    $("#traffic-counts").textContent = `(${c.tx} sent, ${c.rx} received, ${c.errors} errors)`;
  }

  renderAlarms(log) {
    const rows = [...log].reverse().slice(0, 200).map((e) => el("tr", { class: e.kind },
      el("td", { class: "time", text: new Date(e.time * 1000).toLocaleTimeString() }), el("td", { text: axisLabel(this.ctx.identity(e.axis)) }),
      el("td", { text: e.kind }), el("td", { text: e.code ?? "" }), el("td", { text: e.text })));
    $("#alarm-log").replaceChildren(el("tr", {}, ...["time", "axis", "event", "code", "text"].map((t) => el("th", { text: t }))),
      ...(rows.length ? rows : [el("tr", {}, el("td", { colspan: 5, class: "muted", text: "no alarm since the GUI started" }))]));
  }

  renderLinks(doc) {
    const errors = [];
    const rows = Object.entries(doc.links).map(([id, l]) => {
      const g = l.gui, c = l.client || {};
      if (g.last_error) errors.push(`${axisLabel(this.ctx.identity(Number(id)))}: ${g.last_error}`);
      return el("tr", {}, el("td", { text: axisLabel(this.ctx.identity(Number(id))) }), el("td", { class: "num", text: fmt(g.calls) }),
        el("td", { class: "num", text: fmt(g.calls_per_s) }),
        el("td", { class: "num", text: g.mean_ms === null ? "–" : fmt(g.mean_ms) }),
        el("td", { class: "num", text: fmt(g.max_ms) }), el("td", { class: "num", text: g.timeouts }),
        el("td", { class: "num", text: c.retries ?? "–" }), el("td", { class: "num", text: g.errors }));
    });
    $("#link-stats").replaceChildren(el("tr", {}, ...["", "round trips", "per s", "mean ms", "max ms", "timeouts", "retries", "errors"]
      .map((t, i) => el("th", { class: i ? "num" : "", text: t }))), ...rows);
    const first = Object.values(doc.links)[0];
    const client = first && first.client ? Object.entries(first.client).map(([k, v]) => `${k} ${v}`).join(" · ") : "";
    const samplers = doc.samplers.filter((s) => s.running).map((s) => `${axisLabel(this.ctx.identity(s.axis))} ${s.source} ${fmt(s.rate_hz)} Hz`).join(", ");
    $("#link-extra").textContent = [errors.length ? `last errors: ${errors.join("; ")}.` : "",
      client ? `connection counters: ${client}.` : "", samplers ? `sampling: ${samplers}.` : ""].filter(Boolean).join(" ");
  }

  renderTraffic() {
    const filter = $("#traffic-filter").value.trim().toLowerCase();
    const pre = $("#traffic");
    const atBottom = pre.scrollTop + pre.clientHeight >= pre.scrollHeight - 4;
    const shown = filter ? this.lines.filter((l) => l.text.toLowerCase().includes(filter)) : this.lines;
    pre.replaceChildren(...shown.slice(-600).map((l) => el("span", { class: l.error ? "err" : l.dir },
      `${l.t.toFixed(3).padStart(10)} s  ${ARROWS[l.dir] || " "}  ${l.text}\n`)));
    if (atBottom) pre.scrollTop = pre.scrollHeight;
  }
}
