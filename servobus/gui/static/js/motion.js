// Motion panel: servo on/off, jog while held, moves in counts/rev/deg, constant speed, waves.
import { api } from "./net.js";
import { $, $$, axisLabel, el, fieldError, fmt, message, readField, readFields } from "./util.js";

const JOG_REPEAT_MS = 150;  // the server stops a jog not repeated within its lease (0.6 s)

export class MotionPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.msg = $("#motion-msg");
    this.jogTimer = null;
    this.jogAxis = null;
    for (const b of $$("#panel-motion [data-action]")) {
      b.addEventListener("click", () => this.run(`/command`, { action: b.dataset.action }, b.textContent));
    }
    $("#move-abs").addEventListener("click", () => this.move(false));
    $("#move-rel").addEventListener("click", () => this.move(true));
    $("#turn-run").addEventListener("click", () => {
      const rpm = readField($("#turn-rpm"));
      if (rpm === null) { this.refused("constant speed"); return; }
      this.run("/turn", { rpm }, "constant speed", $("#turn-rpm"));
    });
    $("#wave-start").addEventListener("click", () => {
      const values = readFields([$("#wave-amp"), $("#wave-hz")]);
      if (values === null) { this.refused("test motion"); return; }
      const [amplitude, hz] = values;
      this.run("/wave", { kind: $("#wave-kind").value, amplitude, hz }, "test motion");
    });
    $("#wave-off").addEventListener("click", () => this.run("/wave", { kind: "off" }, "test motion off"));
    for (const [id, sign] of [["#jog-plus", 1], ["#jog-minus", -1]]) this.bindJog($(id), sign);
    window.addEventListener("blur", () => this.jogEnd());
    document.addEventListener("visibilitychange", () => { if (document.hidden) this.jogEnd(); });
    ctx.onSelect(() => { this.jogEnd(); this.renderSelection(); });
    ctx.onStatus(() => this.renderReadout());
    this.renderSelection();
  }

  url(path) { return `/api/axes/${this.ctx.selected}${path}`; }

  // ``field``: where a refusal of the server (range, soft limits) is shown as well.
  async run(path, body, what, field = null) {
    try {
      await api(this.url(path), body);
      message(this.msg, `${what}: sent to ${axisLabel(this.ctx.identity(this.ctx.selected))}`, "ok");
    } catch (err) {
      message(this.msg, `${what}: ${err.message}`, "error");
      if (field && err.status === 400) fieldError(field, err.message);
    }
  }

  // A field refused the input (its own message says why): nothing was sent.
  refused(what) { message(this.msg, `${what}: not sent - correct the marked field`, "error"); }

  move(relative) {
    const what = relative ? "move by" : "move to";
    const field = $("#move-value");
    const value = readField(field);
    if (value === null) { this.refused(what); return; }
    const unit = $("#move-unit").value;
    this.run("/move", { value, unit, relative }, `${what} ${value} ${unit}`, field);
  }

  bindJog(button, sign) {
    const start = (ev) => {
      ev.preventDefault();
      button.setPointerCapture?.(ev.pointerId);
      button.classList.add("held");
      this.jogStart(sign);
    };
    const end = () => { button.classList.remove("held"); this.jogEnd(); };
    button.addEventListener("pointerdown", start);
    for (const type of ["pointerup", "pointercancel", "lostpointercapture"]) button.addEventListener(type, end);
    button.addEventListener("contextmenu", (ev) => ev.preventDefault());
  }

  jogStart(sign) {
    this.jogEnd();
    const speed = readField($("#jog-rpm"));
    if (speed === null) { this.refused("jog"); return; }
    const rpm = sign * speed;
    const axis = this.ctx.selected;
    const send = () => {
      if (!this.ctx.link.send({ type: "jog", axis, rpm })) {
        message(this.msg, "jog: no connection to the server", "error");
        this.jogEnd();
      }
    };
    this.jogAxis = axis;
    send();
    this.jogTimer = setInterval(send, JOG_REPEAT_MS);
    message(this.msg, `jogging axis ${axis} at ${rpm} rpm`, "ok");
  }

  jogEnd() {
    if (this.jogTimer === null) return;
    clearInterval(this.jogTimer);
    this.jogTimer = null;
    this.ctx.link.send({ type: "jog_stop", axis: this.jogAxis });
    for (const b of $$("button.jog")) b.classList.remove("held");
    message(this.msg, `jog of axis ${this.jogAxis} released`, "");
    this.jogAxis = null;
  }

  renderSelection() {
    const ident = this.ctx.identity(this.ctx.selected);
    const waves = ident.features.includes("waves");
    for (const node of $$("#wave-box button, #wave-box input, #wave-box select")) node.disabled = !waves;
    $("#wave-hint").textContent = waves
      ? "Amplitude in the drive's own wave units (DMM: 4096 = 180°); the wave runs until Off or Stop."
      : `${ident.family_title} drives have no drive-generated test motion.`;
    // a machine axis moves in its own unit first (limits checked by the server)
    const units = [...new Set([ident.unit, "rev", "deg", "counts"].filter(Boolean))];
    const unitSel = $("#move-unit");
    unitSel.replaceChildren(...units.map((u) => el("option", { value: u, text: u })));
    unitSel.value = units[0];
    const limits = ident.limits ? `; soft limits ${ident.limits[0]} … ${ident.limits[1]} ${ident.unit}` : "";
    const own = ident.unit && ident.unit !== "counts" ? `1 ${ident.unit} = ${fmt(ident.counts_per_unit)} counts; ` : "";
    $("#move-hint").textContent = `${own}1 rev = ${ident.counts_per_rev.toLocaleString("en-US")} counts on ${ident.family_title}${limits}.`;
    this.renderReadout();
  }

  renderReadout() {
    const s = this.ctx.status.get(this.ctx.selected) || {};
    const box = $("#motion-readout");
    const item = (k, v, big = true) => el("div", {}, el("span", { class: "k", text: k }),
      el("span", { class: big ? "big" : "", text: v }));
    box.replaceChildren(
      item(`${axisLabel(this.ctx.identity(this.ctx.selected))} position`,
        s.unit !== undefined ? `${fmt(s.user_position)} ${s.unit}` : `${fmt(s.position)} counts`),
      item("revolutions", s.revolutions === undefined ? "–" : s.revolutions.toFixed(4)),
      item("speed", s.unit !== undefined ? `${fmt(s.user_speed)} ${s.speed_unit}` : `${fmt(s.speed)} rpm`),
      item("current", `${fmt(s.current)} A`),
      item("state", s.link ? "link error" : s.alarm_code ? `ALARM ${s.alarm_code}` :
        `${s.enabled ? "enabled" : "disabled"}${s.moving ? ", moving" : ""}${s.in_position ? ", in position" : ""}`, false));
  }
}
