// I/O panel: a virtual drive's JP3 inputs (analog, pulse train, ENA) and live outputs/state.
// The tab shows only for an axis with virtual I/O (identity.virtual_io).
import { api } from "./net.js";
import { $, axisLabel, el, fmt, message, readField, readFields } from "./util.js";

const OUTPUTS = [  // [label, outputs field, title]
  ["ALM", "alarm", "JP3-8: LOW while an alarm is latched"],
  ["ONPOS", "on_position", "JP3-9: HIGH when on position"],
  ["BKO", "brake_released", "JP3-9 as BKO (OnRange 127): brake released"],
  ["ZRI", "zero_index", "JP3-10: LOW at the encoder's zero index"],
];
const STATE = [  // [label, state field, unit]
  ["servo", "servo", ""], ["alarm", "alarm", ""], ["reference", "reference", "counts"],
  ["following error", "following_error", "counts"], ["speed", "speed_rpm", "rpm"],
  ["current", "current_a", "A"], ["analog in", "inputs.analog_v", "V"], ["ENA", "inputs.ena", ""],
  ["pulse format", "inputs.pulse_format", ""], ["bus", "bus_voltage", "V"],
  ["temperature", "temperature_c", "°C"],
];
const ANALOG_SEND_MS = 80;  // slider drags are sent at most this often

function field(doc, path) {
  return path.split(".").reduce((v, k) => (v === undefined || v === null ? v : v[k]), doc);
}

export class IoPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.msg = $("#io-msg");
    this.visible = false;
    this.last = null;
    this.analogTimer = null;
    this.pendingVolts = null;
    ctx.io = this;  // for the browser tests
    ctx.link.on("io", (doc) => { if (doc.axis === ctx.selected) this.render(doc); });
    ctx.onSelect(() => this.select());
    ctx.link.onState((state) => {  // a new WebSocket watches nothing until told
      if (state === "live" && this.visible && this.hasIo) ctx.link.send({ type: "io_watch", axis: ctx.selected });
    });
    const slider = $("#io-analog"), num = $("#io-analog-num");
    slider.addEventListener("input", () => { num.value = slider.value; this.analog(Number(slider.value)); });
    num.addEventListener("change", () => {
      const v = readField(num);  // refused text: shown at the field, nothing sent
      if (v === null) { message(this.msg, "analog: not sent - correct the marked field", "error"); return; }
      slider.value = v;
      this.analog(v);
    });
    $("#io-analog-zero").addEventListener("click", () => { slider.value = num.value = 0; this.analog(0); });
    $("#io-ena").addEventListener("change", (ev) => this.write({ ena: ev.target.checked }, "ENA"));
    $("#io-pulse-send").addEventListener("click", () => this.sendPulses());
    $("#io-config-set").addEventListener("click", () => this.setConfig());
    this.select();
  }

  get hasIo() { return !!(this.ctx.identity(this.ctx.selected) || {}).virtual_io; }
  url(path) { return `/api/axes/${this.ctx.selected}${path}`; }

  select() {
    const has = this.hasIo;
    $("#tab-io").classList.toggle("hidden", !has);
    $("#io-none").classList.toggle("hidden", has);
    $("#io-body").classList.toggle("hidden", !has);
    this.last = null;
    if (this.visible) {
      if (!has && this.ctx.showTab) { this.ctx.showTab("motion"); return; }
      this.load();
    }
  }

  show() { this.visible = true; this.load(); }
  hide() { this.visible = false; this.ctx.link.send({ type: "io_watch", axis: null }); }

  async load() {
    if (!this.hasIo) return;
    const axis = this.ctx.selected;
    this.ctx.link.send({ type: "io_watch", axis });
    try {
      const doc = await api(this.url("/io"));
      this.limits(doc.limits);
      this.render(doc);
      $("#io-ena").checked = !!doc.state.inputs.ena;
      $("#io-analog").value = $("#io-analog-num").value = doc.state.inputs.analog_v;
    } catch (err) {
      message(this.msg, `I/O: ${err.message}`, "error");
    }
    await this.loadConfig();
  }

  limits(lim) {
    for (const id of ["#io-analog", "#io-analog-num"]) {
      $(id).min = lim.analog_v[0];
      $(id).max = lim.analog_v[1];
    }
    $("#io-pulse-rate").max = lim.pulse_rate_hz[1];
    const sel = $("#io-pulse-format");
    sel.replaceChildren(el("option", { value: "", text: "drive's format" }),
      ...lim.pulse_formats.map((f) => el("option", { value: f, text: f })));
  }

  async loadConfig() {
    const box = $("#io-config-box");
    const fam = this.ctx.identity(this.ctx.selected);
    box.classList.toggle("hidden", !fam.capabilities.includes("config"));
    if (!fam.capabilities.includes("config")) return;
    try {
      this.fillConfig(await api(this.url("/config")));
    } catch (err) {
      message(this.msg, `config: ${err.message}`, "error");
    }
  }

  fillConfig(cfg) {
    for (const [name, id] of [["command_mode", "#io-command-mode"], ["servo_mode", "#io-servo-mode"]]) {
      $(id).replaceChildren(...cfg.choices[name].map((c) => el("option", { value: c, text: c })));
      $(id).value = cfg[name];
    }
  }

  async setConfig() {
    const body = { command_mode: $("#io-command-mode").value, servo_mode: $("#io-servo-mode").value };
    try {
      const doc = await api(this.url("/config"), body);
      this.fillConfig(doc.config);
      message(this.msg, `config: ${doc.config.command_mode} command, ${doc.config.servo_mode} mode`
        + (doc.changed ? " (1 EEPROM write)" : " (unchanged)"), "ok");
    } catch (err) {
      message(this.msg, `config: ${err.message}`, "error");
    }
  }

  analog(volts) {  // coalesce a slider drag: the newest value goes at most every ANALOG_SEND_MS
    this.pendingVolts = volts;
    if (this.analogTimer !== null) return;
    const flush = async () => {
      const v = this.pendingVolts;
      this.pendingVolts = null;
      if (v === null) { this.analogTimer = null; return; }
      await this.write({ analog_v: v }, `analog ${v} V`);
      this.analogTimer = setTimeout(flush, ANALOG_SEND_MS);
    };
    this.analogTimer = 0;
    flush();
  }

  sendPulses() {
    const values = readFields([$("#io-pulse-count"), $("#io-pulse-rate")]);
    if (values === null) { message(this.msg, "pulse train: not sent - correct the marked field", "error"); return; }
    const [count, rate] = values;
    const train = { count, rate };
    if ($("#io-pulse-format").value) train.format = $("#io-pulse-format").value;
    this.write({ pulses: train }, "pulse train");
  }

  async write(body, what) {
    try {
      const doc = await api(this.url("/io"), body);
      this.render(doc);
      const p = doc.replies.pulses;
      const extra = p ? (p.ignored ? " – ignored (not in a pulse command mode, or servo off)"
        : ` – ${fmt(p.taken)} pulses taken over ${fmt(p.seconds)} s (${p.format})`) : "";
      message(this.msg, `${what}: sent to ${axisLabel(this.ctx.identity(this.ctx.selected))}${extra}`, p && p.ignored ? "error" : "ok");
    } catch (err) {
      message(this.msg, `${what}: ${err.message}`, "error");
    }
  }

  render(doc) {
    this.last = doc;
    const out = doc.outputs;
    $("#io-outputs").replaceChildren(...OUTPUTS.map(([label, key, title]) => {
      const v = out[key];
      return el("span", {
        class: `light ${key === "alarm" ? "alarm " : ""}${v ? "on" : ""}`, title,
        "data-output": key, "data-value": v === null ? "n/a" : String(v),
        text: v === null ? `${label} –` : label,
      });
    }));
    $("#io-pins").textContent = `pins: 8 ${out.pins["8"]} · 9 ${out.pins["9"]} · 10 ${out.pins["10"]}`
      + ` · ZRI count ${fmt(out.zri_count)}${out.powered ? "" : " · no power"}`;
    $("#io-state").replaceChildren(...STATE.map(([label, key, unit]) => {
      const v = field(doc.state, key);
      return el("div", { "data-state": key }, el("span", { class: "k", text: label }),
        el("span", { text: `${fmt(typeof v === "boolean" ? (v ? "on" : "off") : v)}${unit ? " " + unit : ""}` }));
    }));
  }
}
