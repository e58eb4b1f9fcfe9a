// The Axes panel: one live card per axis (status lights, position, speed, current, alarm).
// A card shows what the page knows and nothing more (issue 29): values older than two
// polling periods, of an offline axis or with the server gone are greyed with their age
// ("last seen N s ago"); a possible power loss or an interrupted motion is shown with
// Acknowledge.
import { $, el, fmt } from "./util.js";
import { recoveryText, seenText } from "./gate.js";

const LIGHTS = [["enabled", "enabled"], ["moving", "moving"], ["in_position", "in position"], ["alarm_code", "alarm"]];

function identText(ident) {
  return `${ident.protocol || "–"} · ${ident.family_title}${ident.unit ? ` · ${ident.unit}` : ""}`;
}

export class AxesPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.cards = new Map();
    const root = $("#axis-cards");
    for (const ident of ctx.info.axes) {
      const card = el("div", { class: "axis-card", "data-axis": ident.id, onclick: () => ctx.select(ident.id) },
        el("div", { class: "head" },
          el("span", { class: "name", text: ident.name ? ident.name : `Axis ${ident.id}`,
            title: ident.name ? `${ident.label || ""} ${ident.url} id ${ident.drive_id}`.trim() : "" }),
          el("span", { class: "ident", "data-v": "ident", text: identText(ident) })),
        el("div", { class: "seen", "data-v": "seen" }),
        el("div", { class: "lights" }, ...LIGHTS.map(([k, label]) =>
          el("span", { class: `light ${k === "alarm_code" ? "alarm" : k}`, "data-light": k, text: label }))),
        el("div", { class: "values" },
          el("span", { class: "k", text: "position" }), el("span", { class: "v", "data-v": "position" }),
          el("span", { class: "k", text: "" }), el("span", { class: "v muted", "data-v": "revolutions" }),
          el("span", { class: "k", text: "speed" }), el("span", { class: "v", "data-v": "speed" }),
          el("span", { class: "k", text: "current" }), el("span", { class: "v", "data-v": "current" })),
        el("div", { class: "alarm-text", "data-v": "alarm" }),
        el("div", { class: "link-text", "data-v": "link" }),
        el("div", { class: "recovery hidden", "data-v": "recovery-box" },
          el("span", { "data-v": "recovery" }),
          el("button", { class: "ack", "data-gate": "server", text: "Acknowledge",
            title: "I have seen it: allow motion again (nothing is sent to the drive)",
            onclick: (ev) => { ev.stopPropagation(); ctx.acknowledge(ident.id); } })));
      root.append(card);
      this.cards.set(ident.id, card);
    }
    ctx.onSelect((id) => { for (const [aid, c] of this.cards) c.classList.toggle("selected", aid === id); });
    ctx.onStatus((status) => this.render(status));
    ctx.onTick(() => this.render(ctx.status));
    ctx.onIdentity(() => {
      for (const [id, card] of this.cards) card.querySelector("[data-v=ident]").textContent = identText(ctx.identity(id));
    });
  }
  render(status) {
    for (const [id, card] of this.cards) {
      const s = status.get(id);
      if (!s) continue;
      const stale = this.ctx.isStale(s);
      card.classList.toggle("offline", s.online === false);
      card.classList.toggle("stale", stale);
      card.dataset.stale = stale ? "1" : "";
      for (const node of card.querySelectorAll("[data-light]")) {
        const k = node.dataset.light;
        node.classList.toggle("on", k === "alarm_code" ? Boolean(s.alarm_code) : Boolean(s[k]));
      }
      const set = (k, text) => { card.querySelector(`[data-v=${k}]`).textContent = text; };
      set("seen", stale ? seenText(this.ctx, s) : "");
      if (s.unit !== undefined) {  // a machine axis: its own unit first, counts below
        set("position", `${fmt(s.user_position)} ${s.unit}`);
        set("revolutions", s.position === undefined ? "" : `${fmt(s.position)} counts`);
        set("speed", `${fmt(s.user_speed)} ${s.speed_unit}`);
      } else {
        set("position", s.position === undefined ? "–" : `${fmt(s.position)} counts`);
        set("revolutions", s.revolutions === undefined ? "" : `${s.revolutions.toFixed(4)} rev`);
        set("speed", `${fmt(s.speed)} rpm`);
      }
      set("current", `${fmt(s.current)} A`);
      set("alarm", s.alarm_code ? `alarm ${s.alarm_code}: ${s.alarm}${s.alarm_latched ? " (latched: Reset clears)" : ""}` : "");
      set("link", s.link || "");
      const recovery = recoveryText(s);
      set("recovery", recovery);
      card.querySelector("[data-v=recovery-box]").classList.toggle("hidden", !recovery);
      card.dataset.position = s.position ?? "";
      card.dataset.userPosition = s.user_position ?? "";
      card.dataset.speed = s.speed ?? "";
    }
  }
}
