// Tuning panel: step test with its figures, before/after comparison, gains apply/revert.
import { AutoTune } from "./autotune.js";
import { api } from "./net.js";
import { $, axisLabel, el, fieldError, fmt, ms, message, readField, readFields, COLORS } from "./util.js";

// A run's figures; positions in the run's own unit (the server converts: issue 33).
const METRICS = [
  ["rise_time_s", "rise time (10–90 %)", ms], ["overshoot_pct", "overshoot", (v) => `${fmt(v)} %`],
  ["settling_time_s", "settling time", (v) => (v === null ? "not settled" : ms(v))],
  ["peak_time_s", "peak time", ms], ["delay_s", "delay (to 2 %)", ms],
  ["following_error_max", "max following error", (v, unit) => (v === null ? "n/a" : `${fmt(v)} ${unit}`)],
  ["steady_state_error", "steady-state error", (v, unit) => `${fmt(v)} ${unit}`],
];
const runUnit = (r) => r.unit || "counts";

export class TuningPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.msg = $("#tuning-msg");
    this.results = [];
    this.gains = [];
    this.selected = new Set();
    this.plot = null;
    this.visible = false;
    this.auto = new AutoTune(ctx, this.msg);
    $("#step-plus").addEventListener("click", () => this.step(1));
    $("#step-minus").addEventListener("click", () => this.step(-1));
    $("#gains-apply").addEventListener("click", () => this.apply());
    $("#gains-revert").addEventListener("click", () => this.revert());
    ctx.onSelect(() => { this.selected.clear(); this.renderUnits(); if (this.visible) this.load(); });
    ctx.onIdentity(() => this.renderUnits());
    this.renderUnits();
  }

  // The step in the axis's own unit first (a mm axis: mm), then the drive's units.
  renderUnits() {
    const ident = this.ctx.identity(this.ctx.selected);
    const units = [...new Set([ident.unit, "rev", "deg", "counts"].filter(Boolean))];
    const sel = $("#step-unit");
    if ([...sel.options].map((o) => o.value).join() === units.join()) return;
    sel.replaceChildren(...units.map((u) => el("option", { value: u, text: u })));
    sel.value = units[0];
  }
  show() { this.visible = true; this.load(); this.auto.load(); }
  hide() { this.visible = false; }
  url(path = "") { return `/api/axes/${this.ctx.selected}/tuning${path}`; }

  async load() {
    try {
      const doc = await api(this.url());
      this.gains = doc.gains;
      this.results = doc.results;
      this.canRevert = doc.can_revert;
      this.previous = doc.previous;
      this.render();
    } catch (err) {
      message(this.msg, `tuning: ${err.message}`, "error");
    }
  }

  async step(sign) {
    const fields = readFields([$("#step-value"), $("#step-duration")]);
    if (fields === null) { message(this.msg, "step: not sent - correct the marked field", "error"); return; }
    const [size, duration] = fields;
    const buttons = [$("#step-plus"), $("#step-minus")];
    buttons.forEach((b) => { b.disabled = true; });
    message(this.msg, "step test running…");
    try {
      const r = await api(this.url("/step"), {
        distance: sign * Math.abs(size), unit: $("#step-unit").value, duration_s: duration });
      const m = r.metrics;
      message(this.msg, `${axisLabel(this.ctx.identity(r.axis))} run ${r.run}, step ${fmt(r.step ?? r.distance)} ${runUnit(r)}: overshoot ${fmt(m.overshoot_pct)} %, rise ${ms(m.rise_time_s)}, settling ${m.settling_time_s === null ? "not settled" : ms(m.settling_time_s)} (${r.samples} samples, ${r.source === "trace" ? "drive trace" : "polled"} ${fmt(r.rate_hz)} Hz)`, "ok");
      $("#tuning-msg").dataset.overshoot = m.overshoot_pct;
      this.selected.add(r.run);
      while (this.selected.size > 2) this.selected.delete([...this.selected][0]);
      await this.load();
    } catch (err) {
      message(this.msg, `step: ${err.message}`, "error");
      if (err.status === 400) fieldError($("#step-value"), err.message);
    } finally {
      buttons.forEach((b) => { b.disabled = false; });
    }
  }

  async apply() {
    const values = {};
    const refused = [];
    for (const input of document.querySelectorAll("#gains-table input")) {
      const g = this.gains.find((x) => x.name === input.dataset.gain);
      const v = readField(input, { integer: true, min: g.minimum, max: g.maximum });
      if (v === null) refused.push(g.name);
      else if (v !== g.value) values[g.name] = v;
    }
    if (refused.length) {
      message(this.msg, `apply: not sent - ${refused.join(", ")}: an integer within the range shown`, "error");
      return;
    }
    if (!Object.keys(values).length) { message(this.msg, "no gain changed"); return; }
    try {
      await api(this.url("/apply"), { values });
      message(this.msg, `applied ${Object.entries(values).map(([k, v]) => `${k}=${v}`).join(", ")} (Revert restores the previous values)`, "ok");
      await this.load();
    } catch (err) {
      message(this.msg, `apply: ${err.message}`, "error");
    }
  }

  async revert() {
    try {
      const doc = await api(this.url("/revert"), {});
      message(this.msg, `reverted to ${Object.entries(doc.restored).map(([k, v]) => `${k}=${v}`).join(", ")}`, "ok");
      await this.load();
    } catch (err) {
      message(this.msg, `revert: ${err.message}`, "error");
    }
  }

  render() {
    const gt = $("#gains-table");
    gt.replaceChildren(el("tr", {}, ...["gain", "drive", "new", "range", "stored"].map((t) => el("th", { text: t }))),
      ...this.gains.map((g) => el("tr", {}, el("td", { text: g.name, title: g.doc }),
        el("td", { class: "num", text: g.value }),
        el("td", {}, el("input", { type: "text", inputmode: "numeric", autocomplete: "off", class: "num", value: g.value,
          "data-gain": g.name, "data-integer": true, "data-min": g.minimum, "data-max": g.maximum })),
        el("td", { class: "num", text: `${g.minimum}..${g.maximum}` }),
        el("td", {}, el("span", { class: `badge ${g.storage}`, text: g.storage.toUpperCase() })))));
    $("#gains-apply").disabled = this.gains.length === 0;
    $("#gains-revert").disabled = !this.canRevert;
    $("#gains-note").textContent = this.gains.length === 0 ? "this family names no gains" :
      this.canRevert ? `Revert restores ${Object.entries(this.previous).map(([k, v]) => `${k}=${v}`).join(", ")}` : "";
    this.renderRuns();
    this.renderPlot();
  }

  renderRuns() {
    const table = $("#runs-table");
    const head = el("tr", {}, ...["", "run", "step", "gains", "overshoot", "rise", "settling", "follow err"].map((t) => el("th", { text: t })));
    const rows = [...this.results].reverse().map((r) => {
      const box = el("input", { type: "checkbox", checked: this.selected.has(r.run) });
      box.addEventListener("change", () => {
        if (box.checked) this.selected.add(r.run); else this.selected.delete(r.run);
        while (this.selected.size > 2) this.selected.delete([...this.selected][0]);
        this.renderRuns(); this.renderPlot();
      });
      const m = r.metrics;
      return el("tr", { "data-run": r.run }, el("td", {}, box), el("td", { text: `#${r.run}` }),
        el("td", { class: "num", text: `${fmt(r.step ?? r.distance)} ${runUnit(r)}` }),
        el("td", { class: "gains", text: Object.entries(r.gains).map(([k, v]) => `${k.replace("_gain", "")} ${v}`).join(" · ") }),
        el("td", { class: "num overshoot", text: `${fmt(m.overshoot_pct)} %` }),
        el("td", { class: "num", text: ms(m.rise_time_s) }),
        el("td", { class: "num", text: m.settling_time_s === null ? "–" : ms(m.settling_time_s) }),
        el("td", { class: "num", text: m.following_error_max === null ? "n/a" : `${fmt(m.following_error_max)} ${runUnit(r)}` }));
    });
    const picked = this.results.filter((r) => this.selected.has(r.run));
    const compare = [];
    if (picked.length === 2) {
      const [a, b] = picked;
      compare.push(el("tr", {}, el("th", { text: "before / after" }), el("th", { class: "num", text: `#${a.run}` }),
        el("th", { class: "num", text: `#${b.run}` })));
      const gainNames = [...new Set([...Object.keys(a.gains), ...Object.keys(b.gains)])];
      for (const g of gainNames) {
        if (a.gains[g] !== b.gains[g]) compare.push(el("tr", {}, el("td", { text: g }), el("td", { class: "num", text: a.gains[g] }), el("td", { class: "num", text: b.gains[g] })));
      }
      for (const [key, label, show] of METRICS) {
        compare.push(el("tr", {}, el("td", { text: label }), el("td", { class: "num", text: show(a.metrics[key], runUnit(a)) }),
          el("td", { class: "num", text: show(b.metrics[key], runUnit(b)) })));
      }
    }
    table.replaceChildren(head, ...rows, ...(compare.length ? [el("tr", {}, el("td", { colspan: 8 }, el("b", { text: "comparison" }))), ...compare] : []));
  }

  renderPlot() {
    const host = $("#step-plot");
    if (this.plot) { this.plot.destroy(); this.plot = null; }
    const picked = this.results.filter((r) => this.selected.has(r.run));
    if (!picked.length) { host.replaceChildren(el("p", { class: "muted", text: "  Run a step test to see its response here." })); return; }
    host.replaceChildren();
    const tables = picked.map((r) => [r.trace.t.map((t) => t * 1000), r.trace.position]);
    const data = picked.length === 1 ? tables[0] : uPlot.join(tables);
    const series = [{ label: "t (ms)" }, ...picked.map((r, i) => ({
      label: `#${r.run} position − start [${runUnit(r)}]`, stroke: COLORS[i * 2], width: 1.5, spanGaps: true,
      points: { show: false } }))];
    const last = picked[picked.length - 1];
    const target = last.step ?? last.distance;
    this.plot = new uPlot({
      width: Math.max(300, host.clientWidth || 500), height: 300, series,
      scales: { x: { time: false } },
      axes: [{ stroke: "#8994a3", grid: { stroke: "#262c35" }, label: "ms after the command" },
        { stroke: "#8994a3", grid: { stroke: "#262c35" }, size: 70 }],
      hooks: { draw: [(u) => {
        const c = u.ctx, y = u.valToPos(target, "y", true);
        c.save(); c.strokeStyle = "#8994a3"; c.setLineDash([4, 4]);
        c.beginPath(); c.moveTo(u.bbox.left, y); c.lineTo(u.bbox.left + u.bbox.width, y); c.stroke(); c.restore();
      }] },
    }, data, host);
  }
}
