// What the page may offer now (issue 29, docs/gui.md): it shows what it knows and nothing
// more. Without the server every control that sends something is disabled (a banner says
// so) until the page's WebSocket is back; an offline axis greys its controls; motion waits
// until a possible power loss is acknowledged.
//
// A control (a fieldset, which disables everything inside it, or a button) names what it
// needs in data-gate: "server" the server; "axis" the selected axis online as well;
// "motion" also no unacknowledged power loss, and a reopened link done being checked.
// Decision: the gate disables the fieldset, not the controls in it, so a control's own
// disabled state (no edits to write, a family without waves) is kept and comes back as it was.
import { $, $$, axisLabel } from "./util.js";

export function gateReason(ctx, level) {
  if (!ctx.serverUp) return "no connection to the servobus GUI server";
  if (level === "server") return null;
  const s = ctx.status.get(ctx.selected);
  const label = axisLabel(ctx.identity(ctx.selected));
  if (s && s.online === false) return `${label} is offline: its link is down and is reopened by itself`;
  if (level === "axis") return null;
  if (s && s.power_lost) return `${label}: the drive may have lost power (${s.power_lost_reason}); motion is refused until it is acknowledged (Acknowledge, on its card)`;
  if (s && s.checking) return `${label}: its link is back and being checked for a power loss`;
  return null;
}

export function applyGates(ctx) {
  for (const node of $$("[data-gate]")) {
    if (node.dataset.title === undefined) node.dataset.title = node.title || "";
    const why = gateReason(ctx, node.dataset.gate);
    node.disabled = why !== null;
    node.title = why || node.dataset.title;
  }
  const note = $("#motion-gate");
  const why = gateReason(ctx, "motion");
  note.textContent = why ? `Motion controls are disabled: ${why}.` : "";
}

// "last seen 3.2 s ago", from the age of a status (seconds) or null (never read).
export function seenText(ctx, s) {
  const age = ctx.ageOf(s);
  const what = !ctx.serverUp ? "no server" : s.online === false ? "offline" : "not updating";
  if (age === null) return `${what} · never seen`;
  return `${what} · last seen ${age < 10 ? age.toFixed(1) : Math.round(age)} s ago`;
}

// The power-loss flag or the interrupted motion of a status, as a sentence ("" if neither).
export function recoveryText(s) {
  if (s.power_lost) return `The drive may have lost power (${s.power_lost_reason}): motion is refused until acknowledged.`;
  if (s.interrupted) return `Motion interrupted by the link drop: ${s.interrupted}; it was not re-sent.`;
  return "";
}
