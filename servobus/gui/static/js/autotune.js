// Tuning tab, "Auto": the tuner on the selected axis (servobus/gui/autotune.py). Asks first
// (the server's question, naming the axis and the distance in its unit), then shows the
// run's progress from the WebSocket status, the before/after table when done; Cancel
// aborts (stop, kept gains back), Revert writes the kept gains back after a finished run.
// The page renews its runs every 150 ms (as a jog): a page that closes or freezes ends them.
import { api } from "./net.js";
import { $, el, fmt, ms, message, readField } from "./util.js";

const RENEW_MS = 150;
const FIGURES = [
  ["rise_s", "rise", ms], ["overshoot_pct", "overshoot", (v) => `${fmt(v)} %`],
  ["settling_s", "settling", (v) => (v === null ? "not settled" : ms(v))],
  ["following_error", "following error", (v, unit) => (v === null ? "n/a" : `${fmt(v)} ${unit}`)],
  ["vibration", "vibration", (v) => vib(v)],
];

// Vibration: the hold current's RMS over the move's peak (servobus/tune/record.py).
function vib(v) { return v === null || v === undefined ? "n/a" : v.toFixed(3); }

export class AutoTune {
  constructor(ctx, msg) {
    this.ctx = ctx;
    this.msg = msg;
    this.runs = {};  // axis -> the server's view of its last run
    this.saves = {};  // axis -> its family saves tuned gains only on request
    this.renewing = new Set();  // axes whose run this page started and that still run
    this.renewTimer = null;
    this.shownAxis = null;
    $("#auto-start").addEventListener("click", () => this.ask());
    $("#auto-go").addEventListener("click", () => this.go());
    $("#auto-no").addEventListener("click", () => this.closeQuestion("not tuned: the question was declined; nothing was moved"));
    $("#auto-cancel").addEventListener("click", () => this.cancel());
    $("#auto-revert").addEventListener("click", () => this.revert());
    ctx.link.on("status", (doc) => this.onStatus(doc));
    ctx.onSelect(() => { this.closeQuestion(); this.renderUnits(); this.render(); this.load(); });
    ctx.onIdentity(() => this.renderUnits());
    this.renderUnits();
  }

  ident() { return this.ctx.identity(this.ctx.selected); }
  unit() { const u = this.ident()?.units; return (u && u.position) || "counts"; }
  url(path = "") { return `/api/axes/${this.ctx.selected}/tuning/auto${path}`; }

  // The distance field in the axis's unit, a quarter turn by default; Auto only where the
  // axis declares tuning gains (its typed capabilities, no family by name).
  renderUnits() {
    const ident = this.ident();
    const can = Boolean(ident && (ident.capabilities || []).includes("tuning"));
    $("#auto-box").classList.toggle("hidden", !can);
    const unit = this.unit();
    if ($("#auto-unit").textContent !== unit) {
      $("#auto-unit").textContent = unit;
      const perCount = ident?.units?.per_count || 1;
      const quarter = ((ident?.counts_per_rev || 4) / 4) * Math.abs(perCount);
      $("#auto-distance").value = String(Number(quarter.toPrecision(4)));
    }
  }

  body(confirmed) {
    const distance = readField($("#auto-distance"));
    if (distance === null) return null;
    return { distance, unit: this.unit(), page: this.ctx.owner, save: $("#auto-save").checked, goal: $("#auto-goal").value, confirmed };
  }

  async ask() {
    const body = this.body(false);
    if (body === null) { message(this.msg, "auto: not asked - correct the marked field", "error"); return; }
    try {
      const doc = await api(this.url(), body);
      this.pending = { axis: this.ctx.selected, body };
      $("#auto-question").textContent = doc.question;
      $("#auto-note").textContent = [doc.note, doc.save_hint ? `gains ${doc.save_hint}` : ""].filter(Boolean).join(" · ");
      $("#auto-confirm").classList.remove("hidden");
    } catch (err) {
      message(this.msg, `auto: ${err.message}`, "error");
    }
  }

  closeQuestion(text = "") {
    this.pending = null;
    $("#auto-confirm").classList.add("hidden");
    if (text) message(this.msg, text);
  }

  async go() {
    const pending = this.pending;
    this.closeQuestion();
    if (!pending || pending.axis !== this.ctx.selected) return;
    try {
      const doc = await api(this.url(), { ...pending.body, confirmed: true });
      this.runs[this.ctx.selected] = doc.run;
      this.renew(this.ctx.selected, true);
      message(this.msg, `auto-tune of ${doc.run.who} started`, "ok");
      this.render();
    } catch (err) {
      message(this.msg, `auto: ${err.message}`, "error");
    }
  }

  async cancel() {
    try {
      const doc = await api(this.url("/cancel"), {});
      this.runs[this.ctx.selected] = doc.run;
      this.render();
    } catch (err) {
      message(this.msg, `cancel: ${err.message}`, "error");
    }
  }

  async revert() {
    try {
      const doc = await api(this.url("/revert"), {});
      const written = Object.entries(doc.restored).map(([k, v]) => `${k}=${v}`).join(", ");
      message(this.msg, written ? `reverted: ${written}` : "the kept gains were already in place", "ok");
      this.ctx.panels?.tuning?.load();
    } catch (err) {
      message(this.msg, `revert: ${err.message}`, "error");
    }
  }

  // Keep renewing ``axis``'s run while ``on``; the timer runs while any run is renewed.
  renew(axis, on) {
    if (on) this.renewing.add(axis); else this.renewing.delete(axis);
    if (this.renewing.size && this.renewTimer === null) {
      this.renewTimer = setInterval(() => {
        for (const a of this.renewing) this.ctx.link.send({ type: "tune_renew", axis: a });
      }, RENEW_MS);
    } else if (!this.renewing.size && this.renewTimer !== null) {
      clearInterval(this.renewTimer);
      this.renewTimer = null;
    }
  }

  onStatus(doc) {
    const runs = doc.tune || {};
    for (const [axis, run] of Object.entries(runs)) {
      this.renew(Number(axis), run.state === "running" && run.mine);
      const before = this.runs[axis];
      this.runs[axis] = run;
      if (before && before.state === "running" && run.state !== "running" && Number(axis) === this.ctx.selected) {
        message(this.msg, `auto-tune of ${run.who}: ${run.message}`, run.state === "done" ? "ok" : "error");
        this.ctx.panels?.tuning?.load();
      }
    }
    this.render();
  }

  render() {
    const run = this.runs[this.ctx.selected];
    const running = Boolean(run && run.state === "running");
    $("#auto-start").disabled = running;
    $("#auto-cancel").disabled = !running;
    // a finished run's kept gains, or those a killed run left (run.restorable)
    $("#auto-revert").disabled = !(run && !running && ((run.result && !run.reverted) || run.restorable));
    $("#auto-save-label").classList.toggle("hidden", !this.canSave());
    const progress = $("#auto-progress");
    if (!run) { this.renderTable({ result: null }); return; }
    const last = run.tried[run.tried.length - 1];
    progress.textContent = running
      ? `${run.who}: ${run.phase} · test move ${run.trials}${last ? ` · gains ${Object.entries(last.gains).map(([k, v]) => `${k} ${v}`).join(", ")} · vibration ${vib(last.vibration)}` : ""} · most vibration seen ${vib(run.max_vibration)}${run.mine ? "" : ` (run by ${run.owner})`}`
      : `${run.who}: ${run.state} - ${run.message}${run.reverted ? " (reverted)" : ""}`;
    progress.dataset.state = run.state;
    this.renderTable(run);
  }

  canSave() { return Boolean(this.saves[this.ctx.selected]); }

  // Whether the selected axis's family saves gains on request (the save box), and its run.
  async load() {
    const axis = this.ctx.selected;
    if (!(this.ident()?.capabilities || []).includes("tuning")) return;
    try {
      const doc = await api(`${this.url()}?page=${this.ctx.owner ?? 0}`);
      this.saves[axis] = doc.can_save;
      if (doc.run) this.runs[axis] = doc.run;
      this.render();
    } catch (err) {
      message(this.msg, `auto: ${err.message}`, "error");
    }
  }

  renderTable(run) {
    const table = $("#auto-table"), gains = $("#auto-gains");
    const r = run.result;
    if (!r) { table.replaceChildren(); gains.replaceChildren(); $("#auto-hint").textContent = ""; return; }
    table.replaceChildren(el("tr", {}, el("th", { text: "" }), ...FIGURES.map(([, label]) => el("th", { text: label }))),
      ...["before", "after"].map((k) => el("tr", { "data-row": k }, el("td", { text: k }),
        ...FIGURES.map(([key, , show]) => el("td", { class: "num", text: show(r[k][key], run.unit) })))));
    gains.replaceChildren(el("tr", {}, ...["gain", "kept", "tuned", "vibrated at"].map((t) => el("th", { text: t }))),
      ...r.gains.map((g) => el("tr", {}, el("td", { text: g.name }), el("td", { class: "num", text: g.kept }),
        el("td", { class: "num", text: g.tuned }), el("td", { class: "num", text: g.vibrated_at ?? "–" }))));
    $("#auto-hint").textContent = `${r.trials} test moves, ${r.writes} gain writes (${r.source === "trace" ? "drive trace" : "polled"}, ${fmt(r.rate_hz)} Hz) · gains ${r.save_hint}${r.saved ? "; saved" : ""}`;
  }
}
