// Motion panel: servo on/off, jog while held, moves in counts/rev/deg, constant speed, waves.
import { api } from "./net.js";
import { $, $$, axisLabel, el, fieldError, fmt, message, readField, readFields, roundFor, setRules, unitsOf } from "./util.js";
import { gateReason, seenText } from "./gate.js";

// The page renews its jog / constant speed this often; the server's lease ends one not
// renewed within its ttl (0.5 s), in the drive too (servobus.gui.jog, docs/gui.md).
const JOG_REPEAT_MS = 150;

export class MotionPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.msg = $("#motion-msg");
    this.jogTimer = null;
    this.jogAxis = null;
    this.turnTimer = null;
    this.turnAxis = null;
    for (const b of $$("#panel-motion [data-action]")) {
      b.addEventListener("click", () => {
        if (b.dataset.action === "stop") this.turnEnd();  // Stop ends this page's constant speed
        this.run(`/command`, { action: b.dataset.action }, b.textContent);
      });
    }
    $("#move-abs").addEventListener("click", () => this.move(false));
    $("#move-rel").addEventListener("click", () => this.move(true));
    $("#turn-run").addEventListener("click", () => this.turnStart());
    $("#wave-start").addEventListener("click", () => {
      const values = readFields([$("#wave-amp"), $("#wave-hz")]);
      if (values === null) { this.refused("test motion"); return; }
      const [amplitude, hz] = values;
      const unit = unitsOf(this.ctx.identity(this.ctx.selected)).position;
      this.run("/wave", { kind: $("#wave-kind").value, amplitude, unit, hz }, `test motion of ${amplitude} ${unit}`, $("#wave-amp"));
    });
    $("#wave-off").addEventListener("click", () => this.run("/wave", { kind: "off" }, "test motion off"));
    for (const [id, sign] of [["#jog-plus", 1], ["#jog-minus", -1]]) this.bindJog($(id), sign);
    window.addEventListener("blur", () => this.jogEnd());
    document.addEventListener("visibilitychange", () => { if (document.hidden) this.jogEnd(); });
    ctx.onSelect(() => { this.jogEnd(); this.renderSelection(); });
    ctx.onIdentity(() => this.renderSelection());
    ctx.onStatus(() => { this.renderReadout(); this.watchLeases(); });
    ctx.onTick(() => this.renderReadout());
    // a refused jog or renewal (another page holds the axis, at soft limit, it ended):
    // said on the page, and the button no longer shows it held
    ctx.link.on("error", (doc) => {
      if (doc.request === "jog" && this.jogTimer !== null) this.jogEnd(`jog: ${doc.message}`, "error");
      if (doc.request === "turn" && this.turnTimer !== null) this.turnEnd(`constant speed: ${doc.message}`, "error");
    });
    this.renderSelection();
  }

  url(path) { return `/api/axes/${this.ctx.selected}${path}`; }

  say(text, kind = "") { message(this.msg, text, kind); }

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
      if (button.matches(":disabled")) return;  // no server, axis offline, power loss (gate.js)
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
    const why = gateReason(this.ctx, "motion");
    if (why) { message(this.msg, `jog: not sent: ${why}`, "error"); return; }
    const field = readField($("#jog-rpm"));
    if (field === null) { this.refused("jog"); return; }
    const speed = sign * field;
    const axis = this.ctx.selected;
    const ident = this.ctx.identity(axis);
    const send = () => {
      if (!this.ctx.link.send({ type: "jog", axis, speed })) {
        message(this.msg, "jog: no connection to the server", "error");
        this.jogEnd();
      }
    };
    this.jogAxis = axis;
    send();
    this.jogTimer = setInterval(send, JOG_REPEAT_MS);
    message(this.msg, `jogging ${axisLabel(ident)} at ${speed} ${unitsOf(ident).speed}`, "ok");
  }

  jogEnd(text, kind = "") {
    if (this.jogTimer === null) return;
    clearInterval(this.jogTimer);
    this.jogTimer = null;
    this.ctx.link.send({ type: "jog_stop", axis: this.jogAxis });
    for (const b of $$("button.jog")) b.classList.remove("held");
    message(this.msg, text ?? `jog of ${axisLabel(this.ctx.identity(this.jogAxis))} released`, kind);
    this.jogAxis = null;
  }

  async turnStart() {
    this.turnEnd();
    const speed = readField($("#turn-rpm"));
    if (speed === null) { this.refused("constant speed"); return; }
    const axis = this.ctx.selected;
    const label = axisLabel(this.ctx.identity(axis));
    const said = `${speed} ${unitsOf(this.ctx.identity(axis)).speed}`;
    if (this.ctx.owner === null) {
      message(this.msg, "constant speed: no connection to the server", "error");
      return;
    }
    try {
      const doc = await api(`/api/axes/${axis}/turn`, { speed, page: this.ctx.owner });
      if (doc.open_ended) {
        message(this.msg, `constant speed ${said} on ${label}: open-ended (continuous axis), runs until Stop`, "ok");
        return;
      }
      if (speed === 0) { message(this.msg, `constant speed of ${label} stopped`, "ok"); return; }
      this.turnAxis = axis;
      $("#turn-run").classList.add("held");
      this.turnTimer = setInterval(() => {
        if (!this.ctx.link.send({ type: "turn", axis, speed })) this.turnEnd("constant speed: no connection to the server", "error");
      }, JOG_REPEAT_MS);
      message(this.msg, `constant speed ${said} on ${label}: held while this page stays open`, "ok");
    } catch (err) {
      message(this.msg, `constant speed: ${err.message}`, "error");
      if (err.status === 400) fieldError($("#turn-rpm"), err.message);
    }
  }

  turnEnd(text, kind = "") {
    if (this.turnTimer === null) return;
    clearInterval(this.turnTimer);
    this.turnTimer = null;
    this.ctx.link.send({ type: "turn_stop", axis: this.turnAxis });
    $("#turn-run").classList.remove("held");
    if (text !== undefined) message(this.msg, text, kind);
    this.turnAxis = null;
  }

  // This page's jog or constant speed: at a soft limit, or ended without the page letting go
  // (Stop, STOP ALL, not renewed in time): the button goes dark and the page says why.
  watchLeases() {
    const seen = (axis, what, end) => {
      if (axis === null) return;
      const label = axisLabel(this.ctx.identity(axis));
      const why = this.ctx.ended[String(axis)];
      const lease = this.ctx.leases[String(axis)];
      if (why) end(`${what} of ${label} ended: ${why}`, "error");
      else if (lease && lease.mine && lease.at_limit) end(`${what} of ${label}: stopped at soft limit`, "error");
    };
    seen(this.jogAxis, "jog", (t, k) => this.jogEnd(t, k));
    seen(this.turnAxis, "constant speed", (t, k) => this.turnEnd(t, k));
  }

  renderSelection() {
    const ident = this.ctx.identity(this.ctx.selected);
    this.renderUnits(ident);
    const waves = ident.capabilities.includes("waves");
    for (const node of $$("#wave-box button, #wave-box input, #wave-box select")) node.disabled = !waves;
    $("#wave-hint").textContent = waves
      ? `Amplitude in ${unitsOf(ident).position}, each way from where it starts; the wave runs until Off or Stop.`
      : `${ident.family_title} drives have no drive-generated test motion.`;
    // a machine axis moves in its own unit first (limits checked by the server)
    const units = [...new Set([ident.unit, "rev", "deg", "counts"].filter(Boolean))];
    const unitSel = $("#move-unit");
    unitSel.replaceChildren(...units.map((u) => el("option", { value: u, text: u })));
    unitSel.value = units[0];
    const limits = ident.limits ? `; soft limits ${ident.limits[0]} … ${ident.limits[1]} ${ident.unit}` : "";
    const own = ident.unit && ident.unit !== "counts" ? `1 ${ident.unit} = ${fmt(ident.counts_per_unit)} counts; ` : "";
    $("#move-hint").textContent = `${own}1 rev = ${ident.counts_per_rev.toLocaleString("en-US")} counts on ${ident.family_title}${limits}.`;
    $("#turn-hint").textContent = ident.continuous
      ? "Continuous axis: constant speed is open-ended; it runs until Stop, also after this page closes."
      : `Held while this page is open: it ends within ${this.ctx.info.jog_lease_s} s when the page closes or loses its connection, and stops at a soft limit.`;
    this.renderReadout();
  }

  // The speed and amplitude fields in the axis's own units (issue 33): on another axis or
  // unit their values start from the machine file's ``speed`` (else 120/300 rpm worth).
  renderUnits(ident) {
    const u = unitsOf(ident);
    for (const id of ["#jog-unit", "#turn-unit"]) $(id).textContent = u.speed;
    $("#wave-unit").textContent = u.position;
    const rpm = u.speed === "rpm";
    const top = roundFor(6000 * Math.abs(u.per_rpm));
    setRules($("#jog-rpm"), rpm ? { integer: true, min: 1, max: 6000 } : { min: 0, max: top, nonzero: true });
    setRules($("#turn-rpm"), rpm ? { integer: true, min: -6000, max: 6000 } : { min: -top, max: top });
    const key = `${ident.id}:${u.speed}:${u.position}`;
    if (key === this.unitsKey) return;
    this.unitsKey = key;
    const speed = (v) => String(roundFor(ident.default_speed ?? v * Math.abs(u.per_rpm)));
    $("#jog-rpm").value = rpm ? "120" : speed(120);
    $("#turn-rpm").value = rpm ? "300" : speed(300);
    const perRev = ident.counts_per_rev * Math.abs(u.per_count);
    $("#wave-amp").value = String(u.position === "counts" ? Math.round(perRev / 32) : Number((perRev / 32).toPrecision(2)));
  }

  renderReadout() {
    const s = this.ctx.status.get(this.ctx.selected) || {};
    const box = $("#motion-readout");
    const stale = this.ctx.isStale(s);
    box.classList.toggle("stale", stale);
    const item = (k, v, big = true) => el("div", {}, el("span", { class: "k", text: k }),
      el("span", { class: big ? "big" : "", text: v }));
    box.replaceChildren(
      item(`${axisLabel(this.ctx.identity(this.ctx.selected))} position`,
        s.unit !== undefined ? `${fmt(s.user_position)} ${s.unit}` : `${fmt(s.position)} counts`),
      // counts stay as the secondary readout of an axis in its own unit (issue 33)
      s.unit !== undefined ? item("counts", fmt(s.position), false)
        : item("revolutions", s.revolutions === undefined ? "–" : s.revolutions.toFixed(4)),
      item("speed", s.unit !== undefined ? `${fmt(s.user_speed)} ${s.speed_unit}` : `${fmt(s.speed)} rpm`),
      item("current", `${fmt(s.current)} A`),
      item("state", stale ? seenText(this.ctx, s) : s.link ? "link error" : s.alarm_code ? `ALARM ${s.alarm_code}` :
        `${s.enabled ? "enabled" : "disabled"}${s.moving ? ", moving" : ""}${s.in_position ? ", in position" : ""}`, false));
  }
}
