// Parameters panel: the family's table (ranges, units, RAM/EEPROM), edit with range check,
// read, write (EEPROM writes counted before), backup download, restore/compare a file.
import { api } from "./net.js";
import { $, axisLabel, el, download, message } from "./util.js";

export class ParamsPanel {
  constructor(ctx) {
    this.ctx = ctx;
    this.msg = $("#params-msg");
    this.rows = [];  // server rows: name, minimum, maximum, default, unit, storage, doc, value
    this.edits = new Map();  // name -> text typed
    this.visible = false;
    $("#params-read").addEventListener("click", () => this.load());
    $("#params-write").addEventListener("click", () => this.write());
    $("#params-discard").addEventListener("click", () => { this.edits.clear(); this.render(); });
    $("#params-backup").addEventListener("click", () => this.backup());
    $("#params-file").addEventListener("change", (ev) => this.compareFile(ev.target));
    ctx.onSelect(() => { this.edits.clear(); this.hideRestore(); if (this.visible) this.load(); });
  }
  show() { this.visible = true; this.load(); }
  hide() { this.visible = false; }
  url(path = "") { return `/api/axes/${this.ctx.selected}/params${path}`; }

  async load() {
    try {
      const doc = await api(this.url());
      this.rows = doc.params;
      this.render();
      message(this.msg, `read ${this.rows.length} parameters from ${axisLabel(this.ctx.identity(doc.axis))}`, "ok");
    } catch (err) {
      message(this.msg, `read: ${err.message}`, "error");
    }
  }

  check(row) {
    const text = this.edits.get(row.name);
    if (text === undefined) return { edited: false };
    const v = Number(text);
    if (text.trim() === "" || !Number.isInteger(v)) return { edited: true, error: "an integer" };
    if (v < row.minimum || v > row.maximum) return { edited: true, error: `${row.minimum}..${row.maximum}` };
    return { edited: v !== row.value, value: v };
  }

  pending() {
    const changes = {};
    let eeprom = 0, invalid = 0;
    for (const row of this.rows) {
      const c = this.check(row);
      if (c.error) invalid++;
      else if (c.edited) { changes[row.name] = c.value; if (row.storage === "eeprom") eeprom++; }
    }
    return { changes, eeprom, invalid, count: Object.keys(changes).length };
  }

  render() {
    const body = $("#params-table tbody");
    body.replaceChildren(...this.rows.map((row) => {
      const c = this.check(row);
      const input = el("input", { type: "number", step: "1", min: row.minimum, max: row.maximum,
        value: this.edits.get(row.name) ?? row.value, "data-param": row.name });
      input.addEventListener("input", () => {
        this.edits.set(row.name, input.value);
        this.refreshRow(tr, row);
        this.renderPending();
      });
      const tr = el("tr", { "data-param": row.name },
        el("td", { text: row.name }), el("td", {}, input),
        el("td", { class: "num drive", text: row.value }),
        el("td", { class: "num", text: `${row.minimum}..${row.maximum}` }),
        el("td", { class: "num", text: row.default ?? "–" }),
        el("td", { text: row.unit }),
        el("td", {}, el("span", { class: `badge ${row.storage}`, text: row.storage.toUpperCase() })),
        el("td", { class: "meaning", text: row.doc }));
      this.refreshRow(tr, row, c);
      return tr;
    }));
    this.renderPending();
  }

  refreshRow(tr, row, c = this.check(row)) {
    tr.classList.toggle("edited", Boolean(c.edited && !c.error));
    tr.classList.toggle("invalid", Boolean(c.error));
    tr.title = c.error ? `${row.name} must be ${c.error}` : "";
  }

  renderPending() {
    const p = this.pending();
    const write = $("#params-write");
    write.disabled = p.count === 0 || p.invalid > 0;
    write.textContent = p.count ? `Write ${p.count} change${p.count > 1 ? "s" : ""}` : "Write changes";
    $("#params-discard").disabled = this.edits.size === 0;
    $("#params-pending").textContent = p.invalid ? `${p.invalid} value(s) out of range` :
      p.count ? `${p.count} pending: ${p.eeprom} EEPROM write${p.eeprom === 1 ? "" : "s"}, ${p.count - p.eeprom} RAM` : "";
  }

  async write() {
    const p = this.pending();
    if (!p.count || p.invalid) return;
    try {
      const doc = await api(this.url(), { values: p.changes });
      this.edits.clear();
      await this.load();
      const failed = doc.failed.length ? `; NOT taken: ${doc.failed.join(", ")}` : "";
      message(this.msg, `wrote ${p.count} parameter(s), ${doc.eeprom_writes} EEPROM write(s)${failed}`,
        failed ? "error" : "ok");
    } catch (err) {
      message(this.msg, `write: ${err.message}`, "error");
    }
  }

  async backup() {
    try {
      const doc = await api(this.url("/backup"));
      const ident = this.ctx.identity(this.ctx.selected);
      download(`servobus-axis${this.ctx.selected}-${ident.family}.json`,
        new Blob([JSON.stringify(doc, null, 2) + "\n"], { type: "application/json" }));
      message(this.msg, `backup of ${Object.keys(doc.params).length} parameters downloaded`, "ok");
    } catch (err) {
      message(this.msg, `backup: ${err.message}`, "error");
    }
  }

  async compareFile(input) {
    const file = input.files[0];
    input.value = "";
    if (!file) return;
    let backup;
    try { backup = JSON.parse(await file.text()); } catch (err) {
      message(this.msg, `${file.name} is not JSON: ${err.message}`, "error");
      return;
    }
    await this.restore(backup, file.name, false);
  }

  async restore(backup, name, apply) {
    try {
      const doc = await api(this.url("/restore"), { backup, apply });
      if (apply) {
        this.hideRestore();
        await this.load();
        const failed = doc.failed.length ? `; NOT taken: ${doc.failed.join(", ")}` : "";
        message(this.msg, `restored ${name}: ${doc.changes} written (${doc.eeprom_writes} EEPROM)${failed}`,
          failed ? "error" : "ok");
      } else {
        this.showRestore(backup, name, doc);
      }
    } catch (err) {
      message(this.msg, `${name}: ${err.message}`, "error");
    }
  }

  showRestore(backup, name, doc) {
    const box = $("#params-restore");
    const rows = doc.rows.map((r) => el("tr", { class: r.file !== r.drive ? "differs" : "" },
      el("td", { text: r.name }), el("td", { class: "num", text: r.file }),
      el("td", { class: "num drive", text: r.drive }),
      el("td", { text: r.file !== r.drive ? "differs" : "same" }),
      el("td", {}, el("span", { class: `badge ${r.storage}`, text: r.storage.toUpperCase() }))));
    const apply = el("button", { text: doc.changes ? `Apply ${doc.changes} change(s) (${doc.eeprom_writes} EEPROM write(s))` : "Nothing to apply",
      onclick: () => this.restore(backup, name, true) });
    apply.disabled = doc.changes === 0;
    box.replaceChildren(
      el("div", { class: "row" }, el("b", { text: `${name} vs ${axisLabel(this.ctx.identity(this.ctx.selected))}` }),
        el("span", { class: "muted", text: ` saved from drive ${doc.saved_from} (${doc.protocol}) · ${doc.changes} of ${doc.rows.length} differ` })),
      el("table", {}, el("thead", {}, el("tr", {}, ...["parameter", "file", "drive", "", "stored"].map((t) => el("th", { text: t })))),
        el("tbody", {}, ...rows)),
      el("div", { class: "row" }, apply, el("button", { text: "Close", onclick: () => this.hideRestore() })));
    box.classList.remove("hidden");
  }

  hideRestore() { $("#params-restore").classList.add("hidden"); }
}
