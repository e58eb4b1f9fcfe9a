// Small DOM and number helpers.

export const $ = (sel, root = document) => root.querySelector(sel);
export const $$ = (sel, root = document) => [...root.querySelectorAll(sel)];

export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null && v !== false) node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) if (c !== null && c !== undefined) node.append(c);
  return node;
}

export function fmt(v, digits = 3) {
  if (v === null || v === undefined || Number.isNaN(v)) return "–";
  if (typeof v !== "number") return String(v);
  if (v === 0) v = 0;  // -0 (a reversed axis at rest) is shown as 0
  if (Number.isInteger(v)) return v.toLocaleString("en-US");
  const a = Math.abs(v);
  if (a >= 1e6 || (a !== 0 && a < 1e-3)) return v.toExponential(digits - 1);
  const decimals = a >= 1000 ? 0 : a >= 100 ? 1 : a >= 10 ? 2 : digits;
  return v.toFixed(decimals);
}

export function ms(seconds) {
  return seconds === null || seconds === undefined ? "–" : `${(seconds * 1000).toFixed(1)} ms`;
}

export function message(node, text, kind = "") {
  node.textContent = text;
  node.className = `msg ${kind}`;
}

export function download(name, blob) {
  const a = el("a", { href: URL.createObjectURL(blob), download: name });
  document.body.append(a);
  a.click();
  setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 1000);
}

// An axis as people know it: its name in the machine file, else its number.
// The units the server shows an axis in (issue 33): a machine file's axis in its own unit
// (mm, deg) and that per second, a bare URL's in counts and rpm; the server converts.
const DRIVE_UNITS = { position: "counts", speed: "rpm", per_count: 1, per_rpm: 1, signals: {} };
export function unitsOf(ident) { return (ident && ident.units) || DRIVE_UNITS; }

// A signal's shown unit on an axis (the server's), else its raw unit.
export function signalUnit(ident, signal) { return unitsOf(ident).signals[signal.name] || signal.unit; }

// A field's checks (see fieldRules), set when the selected axis's unit changes.
export function setRules(input, { integer = false, min, max, nonzero = false } = {}) {
  const d = input.dataset;
  if (integer) d.integer = ""; else delete d.integer;
  if (nonzero) d.nonzero = ""; else delete d.nonzero;
  if (min === undefined) delete d.min; else d.min = min;
  if (max === undefined) delete d.max; else d.max = max;
}

// A number rounded for a field (no float noise such as 49.99999999).
export function roundFor(v) { return Number(v.toPrecision(6)); }

export function axisLabel(ident) {
  return ident && ident.name ? ident.name : `axis ${ident ? ident.id : "?"}`;
}

export const COLORS = ["#4da3ff", "#ffb84d", "#3ecf6e", "#ff6b9a", "#b48cff", "#43d1d1", "#e6e65c", "#ff7f50"];

// ---------------------------------------------------------------- numbers typed by people
// Decision (issue 28): a numeric field is read from its own text, never from what a browser
// makes of it (an <input type="number"> gives "" for "abc" and for "", and a field read as
// Number("") moved an axis to 0). Empty, non-numeric ("abc", "-", "fast"), non-finite
// ("1e999") and out-of-range text is refused with a message at the field, and nothing is
// sent. A comma is refused too, never dropped: "12,5" is 12.5 to some and 125 to others
// (a thousands separator), so the field asks for a decimal point instead of guessing.
const NUMBER_TEXT = /^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$/;

// parseNumber("12,5", { integer, min, max, nonzero }) -> { value } or { error }
export function parseNumber(text, { integer = false, min = -Infinity, max = Infinity, nonzero = false } = {}) {
  const t = String(text ?? "").trim();
  if (t === "") return { error: "enter a number" };
  if (t.includes(",")) return { error: `"${t}": write a decimal point (12.5), no comma` };
  if (!NUMBER_TEXT.test(t)) return { error: `"${t}" is not a number` };
  const value = Number(t);
  if (!Number.isFinite(value)) return { error: `${t} is too large` };
  if (integer && !Number.isInteger(value)) return { error: `${t}: a whole number` };
  if (value < min || value > max) {
    const range = max === Infinity ? `at least ${min}` : min === -Infinity ? `at most ${max}` : `${min} … ${max}`;
    return { error: `${t} is out of range: ${range}` };
  }
  if (nonzero && value === 0) return { error: "not 0" };
  return { value };
}

// The error span of a field: the element right after it (made on first use).
function errorNode(input) {
  let node = input.nextElementSibling;
  if (!node || !node.classList.contains("field-error")) {
    node = el("span", { class: "field-error", role: "alert" });
    if (input.id) node.id = `${input.id}-error`;
    input.after(node);
  }
  return node;
}

export function fieldError(input, text) {
  const node = errorNode(input);
  node.textContent = text;
  input.classList.toggle("invalid", !!text);
  if (text) input.setAttribute("aria-invalid", "true"); else input.removeAttribute("aria-invalid");
  if (input.id) input.setAttribute("aria-describedby", node.id);
}

// The checks of a field from its data attributes: data-integer, data-min, data-max, data-nonzero.
export function fieldRules(input) {
  const d = input.dataset;
  const num = (v, fallback) => (v === undefined || v === "" ? fallback : Number(v));
  return { integer: "integer" in d, min: num(d.min, -Infinity), max: num(d.max, Infinity), nonzero: "nonzero" in d };
}

// The field's number, or null after showing why not at the field (nothing may be sent then).
export function readField(input, rules = fieldRules(input)) {
  const r = parseNumber(input.value, rules);
  fieldError(input, r.error || "");
  return r.error ? null : r.value;
}

// Read several fields at once: every one shows its own error; null if any is refused.
export function readFields(inputs) {
  const values = inputs.map((input) => readField(input));
  return values.some((v) => v === null) ? null : values;
}
