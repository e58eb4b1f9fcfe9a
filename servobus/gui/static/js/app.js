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
  }
  identity(id) { return this.info.axes.find((a) => a.id === id); }
  select(id) {
    this.selected = id;
    for (const fn of this.selectListeners) fn(id);
  }
  onSelect(fn) { this.selectListeners.push(fn); }
  onStatus(fn) { this.statusListeners.push(fn); }
  setStatus(doc) {
    for (const snap of doc.axes) this.status.set(snap.id, snap);
    this.jogs = doc.jog || {};
    this.leases = doc.leases || {};
    this.ended = doc.ended || {};
    for (const fn of this.statusListeners) fn(this.status);
  }
  async stopAll() {
    if (!this.link.send({ type: "stop_all" })) await api("/api/stop_all", {});
  }
}

async function main() {
  const info = await api("/api/info");
  const link = new Link();
  const ctx = new Context(info, link);
  window.servobus = ctx;  // for people poking around, and for the browser tests
  $("#conn-url").textContent = info.machine ? `machine ${info.machine} · ${info.url}` : info.url;
  link.onState((state) => {
    const node = $("#conn");
    node.dataset.state = state;
    node.textContent = { live: "● live", down: "● connection lost – retrying", connecting: "connecting…" }[state];
  });
  link.on("hello", (doc) => { ctx.owner = doc.owner; });
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
  ctx.onSelect((id) => { $("#tab-axis").textContent = `${axisLabel(ctx.identity(id))} · ${ctx.identity(id).family_title}`; });
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
