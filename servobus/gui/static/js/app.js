// The servobus GUI page: one WebSocket, the Axes panel, and one module per tab.
import { api, Link } from "./net.js";
import { $, $$, axisLabel } from "./util.js";
import { AxesPanel } from "./axes.js";
import { MotionPanel } from "./motion.js";
import { ParamsPanel } from "./params.js";
import { ScopePanel } from "./scope.js";
import { TuningPanel } from "./tuning.js";
import { DiagnosticsPanel } from "./diagnostics.js";
import { IoPanel } from "./io.js";
import { applyGates } from "./gate.js";

// Ages and gates are redrawn this often even when no status arrives (the server gone).
const TICK_MS = 500;
// No status for this long (the server pushes one every 0.1 s): every value is stale.
const STATUS_LATE_MS = 1000;

class Context {
  constructor(info, link) {
    this.info = info;
    this.link = link;
    this.status = new Map();
    this.jogs = {};
    this.leases = {};  // axis -> {owner, rpm, at_limit, mine}: every running jog/constant speed
    this.ended = {};  // axis -> why this page's jog/constant speed ended without it letting go
    this.owner = null;  // this page's WebSocket session ("page N" owns its motions)
    this.selected = info.axes[0].id;
    this.selectListeners = [];
    this.statusListeners = [];
    this.identityListeners = [];
    this.tickListeners = [];
    this.serverUp = false;  // the page's WebSocket is open (issue 29: else every control is off)
    this.serverLost = false;  // it was lost since the page loaded: the banner shows until it is back
    this.statusAt = performance.now();  // when the last status arrived (ages count on from it)
    this.refreshing = false;
  }
  identity(id) { return this.info.axes.find((a) => a.id === id); }
  onIdentity(fn) { this.identityListeners.push(fn); }
  onTick(fn) { this.tickListeners.push(fn); }
  tick() { for (const fn of this.tickListeners) fn(); }
  // Seconds since the status's values were read (the server's age plus the time since it
  // said so), or null when the axis was never read.
  ageOf(s) {
    if (!s || s.age_s === null || s.age_s === undefined) return null;
    return s.age_s + (performance.now() - this.statusAt) / 1000;
  }
  // Values are stale without the server, on an offline axis, older than two polling
  // periods (the server's "stale", judged when it sent the status), or once statuses
  // stop coming (a server that hangs with its socket open).
  isStale(s) {
    if (!s || !this.serverUp || s.online === false || s.stale !== false) return true;
    return performance.now() - this.statusAt > STATUS_LATE_MS;
  }
  setServer(up) {
    this.serverUp = up;
    this.serverLost = !up;
    this.tick();
  }
  // The axes a (re)connected server serves: the same ones are updated in place (an axis
  // that came online has its family now); another machine reloads the page.
  updateIdentities(axes) {
    const mine = this.info.axes;
    const same = axes.length === mine.length
      && axes.every((a, i) => a.id === mine[i].id && (a.name || "") === (mine[i].name || ""));
    if (!same) { location.reload(); return; }
    const changed = axes.filter((a, i) => JSON.stringify(a) !== JSON.stringify(mine[i]));
    axes.forEach((a, i) => Object.assign(mine[i], a));
    if (changed.length) for (const fn of this.identityListeners) fn();
  }
  async refreshIdentities() {
    if (this.refreshing) return;
    this.refreshing = true;
    try { this.updateIdentities((await api("/api/info")).axes); } catch { /* the next status asks again */ }
    this.refreshing = false;
  }
  async acknowledge(id) {
    const label = axisLabel(this.identity(id));
    try {
      await api(`/api/axes/${id}/acknowledge`, {});
      this.panels.motion.say(`${label}: acknowledged; motion is allowed again`, "ok");
    } catch (err) {
      this.panels.motion.say(`acknowledge ${label}: ${err.message}`, "error");
    }
  }
  select(id) {
    this.selected = id;
    for (const fn of this.selectListeners) fn(id);
  }
  onSelect(fn) { this.selectListeners.push(fn); }
  onStatus(fn) { this.statusListeners.push(fn); }
  setStatus(doc) {
    this.statusAt = performance.now();
    for (const snap of doc.axes) {
      this.status.set(snap.id, snap);
      // an axis offline when the page loaded is online now: ask for its family, units ...
      if (snap.online && this.identity(snap.id)?.family === "") this.refreshIdentities();
    }
    this.jogs = doc.jog || {};
    this.leases = doc.leases || {};
    this.ended = doc.ended || {};
    for (const fn of this.statusListeners) fn(this.status);
  }
  async stopAll() {
    if (!this.serverUp) return;  // the banner says so; the button is disabled
    if (this.link.send({ type: "stop_all" })) return;
    try { await api("/api/stop_all", {}); } catch (err) { this.panels.motion.say(`STOP ALL: ${err.message}`, "error"); }
  }
}

async function main() {
  const info = await api("/api/info");
  const link = new Link();
  const ctx = new Context(info, link);
  window.servobus = ctx;  // for people poking around, and for the browser tests
  $("#conn-url").textContent = info.machine ? `machine ${info.machine} · ${info.url}` : info.url;
  link.onState((state, why) => {
    const node = $("#conn");
    node.dataset.state = state;
    node.textContent = { live: "● live", down: "● connection lost – retrying", connecting: "connecting…" }[state];
    if (state === "live") ctx.setServer(true);
    else if (state === "down" || ctx.serverUp) ctx.setServer(false);  // not the first connecting
    $("#server-banner").classList.toggle("hidden", !ctx.serverLost);
    if (state === "down") $("#server-banner-why").textContent = why ? ` (it said: ${why})` : "";
  });
  link.on("hello", (doc) => {
    ctx.owner = doc.owner;
    if (doc.axes) ctx.updateIdentities(doc.axes);
  });
  link.on("status", (doc) => ctx.setStatus(doc));
  link.on("error", (doc) => console.warn("server:", doc.message));

  const panels = {
    motion: new MotionPanel(ctx), params: new ParamsPanel(ctx), scope: new ScopePanel(ctx),
    tuning: new TuningPanel(ctx), diag: new DiagnosticsPanel(ctx), io: new IoPanel(ctx),
  };
  ctx.panels = panels;
  panels.motion.bindJog($("#scope-jog-plus"), 1);  // jog while watching the scope
  panels.motion.bindJog($("#scope-jog-minus"), -1);
  new AxesPanel(ctx);
  let active = "motion";
  const show = (name) => {
    active = name;
    for (const b of $$("#tabs button")) b.classList.toggle("active", b.dataset.tab === name);
    for (const p of $$(".panel")) p.classList.toggle("hidden", p.dataset.panel !== name);
    for (const [n, panel] of Object.entries(panels)) (n === name ? panel.show : panel.hide)?.call(panel);
  };
  for (const b of $$("#tabs button")) b.addEventListener("click", () => show(b.dataset.tab));
  ctx.showTab = show;
  const tabAxis = () => { const id = ctx.selected; $("#tab-axis").textContent = `${axisLabel(ctx.identity(id))} · ${ctx.identity(id).family_title}`; };
  ctx.onSelect(tabAxis);
  ctx.onIdentity(tabAxis);
  ctx.onSelect(() => applyGates(ctx));
  ctx.onStatus(() => applyGates(ctx));
  ctx.onTick(() => applyGates(ctx));
  setInterval(() => ctx.tick(), TICK_MS);
  ctx.select(ctx.selected);
  show(location.hash.slice(1) in panels ? location.hash.slice(1) : active);

  $("#stop-all").addEventListener("click", () => ctx.stopAll());
  document.addEventListener("keydown", (ev) => {
    if (ev.key === "Escape") { ev.preventDefault(); ctx.stopAll(); }
  });
  document.body.dataset.ready = "1";
}

main().catch((err) => {
  document.body.dataset.ready = "error";
  $("#conn").textContent = `error: ${err.message}`;
  console.error(err);
});
