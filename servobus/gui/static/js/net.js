// REST and WebSocket to the servobus GUI server (same origin; token from the page URL).

const TOKEN = new URLSearchParams(location.search).get("token");
// This page's WebSocket number (hello's owner): its requests count against its own limits
// on the server (servobus/gui/fair.py), not against every page of this computer.
let PAGE = null;

export class ApiError extends Error {
  constructor(message, status = 0) { super(message); this.status = status; }
}

// GET (no body) or POST JSON; resolves to the JSON answer, rejects with the server's text.
export async function api(path, body) {
  const headers = {};
  if (TOKEN) headers["X-Servobus-Token"] = TOKEN;
  if (PAGE !== null) headers["X-Servobus-Page"] = String(PAGE);
  const init = { headers, credentials: "same-origin" };
  if (body !== undefined) {
    init.method = "POST";
    headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  let res;
  try {
    res = await fetch(path, init);
  } catch {  // the browser's "Failed to fetch": say what it means
    throw new ApiError("no answer from the servobus GUI server (is it running?)", 0);
  }
  let doc = null;
  try { doc = await res.json(); } catch { /* not JSON */ }
  if (!res.ok) throw new ApiError((doc && doc.error) || `${res.status} ${res.statusText}`, res.status);
  return doc;
}

// The page's WebSocket: reconnects by itself; onJson(type) handlers, onBinary for frames.
export class Link {
  constructor() {
    this.handlers = new Map();
    this.binary = null;
    this.stateListeners = [];
    this.ws = null;
    this.retry = 250;
    this.connect();
  }
  get open() { return this.ws !== null && this.ws.readyState === WebSocket.OPEN; }
  on(type, fn) {
    if (!this.handlers.has(type)) this.handlers.set(type, []);
    this.handlers.get(type).push(fn);
  }
  onState(fn) { this.stateListeners.push(fn); }
  // state: "connecting", "live" or "down"; why: the server's reason when it closed the socket
  setState(state, why = "") { for (const fn of this.stateListeners) fn(state, why); }
  connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const q = TOKEN ? `?token=${encodeURIComponent(TOKEN)}` : "";
    const ws = new WebSocket(`${proto}://${location.host}/ws${q}`);
    ws.binaryType = "arraybuffer";
    this.ws = ws;
    this.setState("connecting");
    ws.onopen = () => { this.retry = 250; this.setState("live"); };
    ws.onclose = (ev) => {
      this.setState("down", ev.reason || "");
      setTimeout(() => this.connect(), this.retry);
      this.retry = Math.min(this.retry * 2, 4000);
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data !== "string") { if (this.binary) this.binary(ev.data); return; }
      const doc = JSON.parse(ev.data);
      if (doc.type === "hello") PAGE = doc.owner;
      for (const fn of this.handlers.get(doc.type) || []) fn(doc);
    };
  }
  send(doc) {
    if (!this.open) return false;
    this.ws.send(JSON.stringify(doc));
    return true;
  }
}
